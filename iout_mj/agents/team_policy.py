"""A decentralised team policy: one actor shared by every AUV, each acting on its own
observation (the PettingZoo env's, padded to fixed sizes), as trained by `training.marl`.

The padded observation of AUV i serves any N <= n_max and K <= k_max with one network:

    own 7 | per node slot (k_max): AoI, energy, distance, present | per other-AUV slot
    (n_max - 1): relative position 2, docked, present | time remaining 1 | one-hot index n_max

Absent slots are zeros with present = 0; the actor's logits for absent nodes are masked, so an
AET or uplink node is always one of the K present. `padded_state` is the env's global
observation (`ParallelEnv.state()`) padded the same way, the centralised critic's input.

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

OWN_FEATURES = 7
NODE_FEATURES = 4
OTHER_FEATURES = 4
ACTION_DIMS = 4
"""(heading, speed, AET node, uplink node) per AUV."""


def team_observation_size(n_max: int, k_max: int) -> int:
    """Entries of one AUV's padded observation (see the module docstring)."""
    return OWN_FEATURES + NODE_FEATURES * k_max + OTHER_FEATURES * (n_max - 1) + 1 + n_max


def node_present_slice(k_max: int) -> slice:
    """Where the node-present flags lie in a padded observation."""
    start = OWN_FEATURES + 3 * k_max
    return slice(start, start + k_max)


def check_fit(n_auvs: int, n_nodes: int, n_max: int, k_max: int) -> None:
    """Refuse a scenario larger than the padded sizes."""
    if not (1 <= n_auvs <= n_max and 1 <= n_nodes <= k_max):
        raise PolicyMismatchError(
            f"a team policy for up to N={n_max} AUVs and K={k_max} nodes cannot fly N={n_auvs}, "
            f"K={n_nodes}: accepted N <= {n_max} and K <= {k_max}"
        )


def padded_observations(m: Mission, n_max: int, k_max: int) -> np.ndarray:
    """(N, team_observation_size) float32: every AUV's own observation, padded. Without its
    present flags and padding it is the PettingZoo env's (`parallel_env.agent_observations`)."""
    n, k = m.n_auvs, m.n_nodes
    check_fit(n, k, n_max, k_max)
    g, positions = m.observation(), m.state.positions_m
    out = np.zeros((n, team_observation_size(n_max, k_max)), dtype=np.float32)
    out[:, 0:2] = g["auv_position"].reshape(n, 2)
    out[:, 2:4] = g["auv_heading"].reshape(n, 2)
    out[:, 4] = g["auv_speed"]
    out[:, 5] = g["docked"]
    out[:, 6] = g["dock_distance"]
    nodes = out[:, OWN_FEATURES : OWN_FEATURES + NODE_FEATURES * k_max].reshape(
        n, NODE_FEATURES, k_max
    )
    nodes[:, 0, :k] = g["aoi"]
    nodes[:, 1, :k] = g["node_energy"]
    nodes[:, 2, :k] = g["distance"].reshape(n, k)
    nodes[:, 3, :k] = 1.0
    at = OWN_FEATURES + NODE_FEATURES * k_max
    others = out[:, at : at + OTHER_FEATURES * (n_max - 1)].reshape(n, n_max - 1, OTHER_FEATURES)
    docked = m.state.docked.astype(np.float32)
    for i in range(n):
        rest = [j for j in range(n) if j != i]
        others[i, : n - 1, 0:2] = (positions[rest] - positions[i]) * m.inv_area
        others[i, : n - 1, 2] = docked[rest]
        others[i, : n - 1, 3] = 1.0
    at += OTHER_FEATURES * (n_max - 1)
    out[:, at] = g["time_remaining"][0]
    out[:, at + 1 : at + 1 + n] = np.eye(n, dtype=np.float32)
    return out


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
        present = torch.as_tensor(obs[:, node_present_slice(self.k_max)])
        return masked_logits(logits, self.nvec, present)

    def __call__(self, env: Any, _obs: np.ndarray) -> np.ndarray:
        obs = padded_observations(env.unwrapped.mission, self.n_max, self.k_max)
        actions = torch.stack([p.argmax(-1) for p in self.logits(obs)], dim=-1)
        return actions.numpy().astype(np.int64).ravel()
