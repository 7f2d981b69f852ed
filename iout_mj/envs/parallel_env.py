"""PettingZoo: the mission as a `ParallelEnv`, one agent per AUV (`auv_0`, `auv_1`, ...).

Each agent observes its own view of the mission (`mission.agent_view`: the clock, its own
pose and docking slack, the other AUVs relative to itself, per node its position, AoI, energy
and its own link), and chooses its own (heading, speed, AET node, uplink node). The reward is the
paper's team reward, the same for every agent; `infos[agent]` holds the team's reward terms
and the agent's own state. `state()` is the global observation of `iout_mj/MultiAUV-v0` (for
a centralised critic). All agents end together: when every AUV docked, a battery is empty,
or at T_max.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from pettingzoo import ParallelEnv

from iout_mj.envs.gym_env import MultiAUVEnv
from iout_mj.mission import OBS_HIGH, OBS_LOW
from iout_mj.mission.actions import ACTION_FIELDS, ActionError
from iout_mj.mission.agent_view import agent_observation_size, agent_observations
from iout_mj.scenarios import ConfigLike


class MultiAUVParallelEnv(ParallelEnv):
    """N AUVs as N agents of one team; arguments as for `gymnasium.make("iout_mj/MultiAUV-v0")`."""

    metadata = {"name": "iout_mj_multi_auv_v0", "render_modes": []}  # noqa: RUF012

    def __init__(
        self,
        n_auvs: int | None = None,
        n_nodes: int | None = None,
        backend: str = "kinematic",
        layout: str | None = None,
        config: ConfigLike = None,
    ):
        self.env = MultiAUVEnv(n_auvs, n_nodes, backend, layout, None, config)
        self.mission = self.env.mission
        n, k = self.mission.n_auvs, self.mission.n_nodes
        self.possible_agents = [f"auv_{i}" for i in range(n)]
        self.agents: list[str] = []
        size = agent_observation_size(n, k)
        self._obs_space = gym.spaces.Box(OBS_LOW, OBS_HIGH, shape=(size,), dtype=np.float32)
        cfg = self.mission.cfg.motion
        self._act_space = gym.spaces.MultiDiscrete([cfg.heading_levels, cfg.speed_levels, k, k])
        self.state_space = self.env.observation_space
        self.render_mode = None

    def observation_space(self, agent: str) -> gym.spaces.Box:
        return self._obs_space

    def action_space(self, agent: str) -> gym.spaces.MultiDiscrete:
        return self._act_space

    def _observe(self) -> dict[str, np.ndarray]:
        obs = agent_observations(self.mission)
        return {a: obs[i] for i, a in enumerate(self.possible_agents)}

    def _infos(self, team: dict[str, Any]) -> dict[str, dict[str, Any]]:
        s = self.mission.state
        return {
            a: {
                **team,
                "docked": bool(s.docked[i]),
                "propulsion_energy_j": float(s.propulsion_energy_j[i]),
            }
            for i, a in enumerate(self.possible_agents)
        }

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict[str, Any]]]:
        self.env.reset(seed=seed)
        self.agents = list(self.possible_agents)
        return self._observe(), self._infos({})

    def _agent_action(self, agent: str, action: Any) -> np.ndarray:
        """One agent's action, checked on its own (a wrong-sized action would otherwise shift
        the entries of the others)."""
        a, high = np.asarray(action), self._act_space.nvec
        if a.shape != high.shape:
            raise ActionError(
                f"actions[{agent!r}] has shape {a.shape}; accepted {high.size} integers "
                f"({', '.join(ACTION_FIELDS)})"
            )
        integral = a.dtype.kind in "iu" or (
            a.dtype.kind == "f" and bool(np.all(np.isfinite(a))) and bool(np.all(a == np.round(a)))
        )
        if not integral or np.any(a < 0) or np.any(a >= high):
            raise ActionError(
                f"actions[{agent!r}] = {a.tolist()} is invalid: accepted integers from 0 to "
                f"{(high - 1).tolist()} ({', '.join(ACTION_FIELDS)})"
            )
        return a.astype(np.int64)

    def step(self, actions: dict[str, Any]) -> tuple[Any, Any, Any, Any, Any]:
        missing = [a for a in self.agents if a not in actions]
        if missing:
            raise ValueError(f"actions: missing for {missing}; accepted one action per agent")
        unknown = sorted(str(a) for a in actions if a not in self.agents)
        if unknown:
            raise ValueError(
                f"actions for {unknown}, which are not live agents: accepted one action for "
                f"each of {self.agents} (after the episode ends, call reset())"
            )
        joint = np.concatenate([self._agent_action(a, actions[a]) for a in self.possible_agents])
        _, reward, terminated, truncated, info = self.env.step(joint)
        agents = self.agents
        obs = self._observe()
        infos = self._infos(info)
        rewards = dict.fromkeys(agents, float(reward))
        terminations = dict.fromkeys(agents, bool(terminated))
        truncations = dict.fromkeys(agents, bool(truncated))
        if terminated or truncated:
            self.agents = []
        return obs, rewards, terminations, truncations, infos

    def state(self) -> np.ndarray:
        """The global observation (the centralised critic's input)."""
        return self.mission.flat_observation()

    def close(self) -> None:
        self.env.close()


def parallel_env(**kwargs: Any) -> MultiAUVParallelEnv:
    """The PettingZoo parallel env: `iout_mj.parallel_env(n_auvs=2, n_nodes=7, ...)`."""
    return MultiAUVParallelEnv(**kwargs)
