"""A decentralised team policy: one actor shared by every AUV, each acting on its own
observation, as trained by `training.marl`.

An AUV's observation is its own view of the mission (`mission.agent_view`: the token
observation as that AUV sees it), padded to n_max AUVs and k_max nodes, so one network serves
any N <= n_max and K <= k_max. The actor's logits for absent nodes are masked, so an AET or
uplink node is always one of the K present. `padded_state` is the env's global observation
(`ParallelEnv.state()`) padded the same way, the centralised critic's input.

A team policy is stored in the safe policy format as an SB3 MLP (the actor's layers; no value
layers) whose manifest has a `team` entry ({algorithm, n_max, k_max}); `TeamPolicy` flies it in
a gymnasium env, one forward pass per AUV on its own observation.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from iout_mj.agents.policy_format import LoadedPolicy
from iout_mj.errors import PolicyMismatchError
from iout_mj.mission import Mission
from iout_mj.mission.agent_view import (
    agent_observation_size,
    agent_observations,
    node_present_slice,
)

ACTION_DIMS = 4
"""(heading, speed, AET node, uplink node) per AUV."""

team_observation_size = agent_observation_size


def check_fit(n_auvs: int, n_nodes: int, n_max: int, k_max: int) -> None:
    """Refuse a scenario larger than the padded sizes."""
    if not (1 <= n_auvs <= n_max and 1 <= n_nodes <= k_max):
        raise PolicyMismatchError(
            f"a team policy for up to N={n_max} AUVs and K={k_max} nodes cannot fly N={n_auvs}, "
            f"K={n_nodes}: accepted N <= {n_max} and K <= {k_max}"
        )


def padded_observations(m: Mission, n_max: int, k_max: int) -> np.ndarray:
    """(N, team_observation_size(n_max, k_max)) float32: every AUV's own view, padded (at
    n_max = N, k_max = K it is the PettingZoo env's agent observation)."""
    check_fit(m.n_auvs, m.n_nodes, n_max, k_max)
    return agent_observations(m, n_max, k_max)


def state_size(n_max: int, k_max: int) -> int:
    """Entries of the padded global state (see `padded_state`)."""
    return 8 * n_max + (3 + n_max) * k_max + 1


def padded_state(m: Mission, n_max: int, k_max: int) -> np.ndarray:
    """(state_size,) float32: the global observation's groups (`Mission.observation`, what
    `ParallelEnv.state()` concatenates), each padded to n_max AUVs and k_max nodes, with
    present flags for both."""
    n, k = m.n_auvs, m.n_nodes
    check_fit(n, k, n_max, k_max)
    g = m.observation()
    auv = np.zeros((n_max, 8), dtype=np.float32)
    auv[:n, 0:2] = g["auv_position"].reshape(n, 2)
    auv[:n, 2:4] = g["auv_heading"].reshape(n, 2)
    auv[:n, 4] = g["auv_speed"]
    auv[:n, 5] = g["docked"]
    auv[:n, 6] = g["dock_distance"]
    auv[:n, 7] = 1.0
    node = np.zeros((3 + n_max, k_max), dtype=np.float32)
    node[0, :k] = g["aoi"]
    node[1, :k] = g["node_energy"]
    node[2, :k] = 1.0
    node[3 : 3 + n, :k] = g["distance"].reshape(n, k)
    return np.concatenate([auv.ravel(), node.ravel(), g["time_remaining"].astype(np.float32)])


def masked_logits(
    logits: torch.Tensor, nvec: list[int], present: torch.Tensor
) -> list[torch.Tensor]:
    """The logits of each action dimension; the node dimensions (the last two) have the logits
    of absent nodes (present = 0) set to the lowest float."""
    parts = list(torch.split(logits, nvec, dim=-1))
    absent = present < 0.5
    low = torch.finfo(logits.dtype).min
    for i in (2, 3):
        parts[i] = parts[i].masked_fill(absent, low)
    return parts


class TeamPolicy:
    """A stored team policy flying a gymnasium env (`rollout.EnvPolicy`): each AUV's action
    from its own padded observation, the most likely action of each dimension."""

    def __init__(self, loaded: LoadedPolicy):
        team = loaded.manifest["team"]
        self.loaded = loaded
        self.n_max, self.k_max = int(team["n_max"]), int(team["k_max"])
        self.nvec = [int(v) for v in loaded.manifest["action_nvec"]]
        self.manifest = loaded.manifest

    def logits(self, obs: np.ndarray) -> list[torch.Tensor]:
        """Masked logits per action dimension for a batch of padded observations."""
        policy = self.loaded.policy
        x = torch.as_tensor(self.loaded.normalizer(obs))
        with torch.no_grad():
            features = policy.extract_features(x)
            assert isinstance(features, torch.Tensor)  # a Box observation: one tensor
            latent = policy.mlp_extractor.forward_actor(features)
            logits = policy.action_net(latent)
        present = torch.as_tensor(obs[:, node_present_slice(self.n_max, self.k_max)])
        return masked_logits(logits, self.nvec, present)

    def __call__(self, env: Any, obs: np.ndarray) -> np.ndarray:
        """The joint action; `obs` is not read: each AUV's padded view comes from the mission."""
        views = padded_observations(env.unwrapped.mission, self.n_max, self.k_max)
        actions = torch.stack([p.argmax(-1) for p in self.logits(views)], dim=-1)
        return actions.numpy().astype(np.int64).ravel()
