"""An SB3 VecEnv over a distribution of scenarios: one `MissionBatch` per cell (a number of
nodes K and an env config, e.g. a noise model), token observations padded to K_MAX and one
action space `MultiDiscrete([H, S, K_MAX, K_MAX] * N)`, so that one policy trains on all
cells at once. The cells share one RNG (layouts and currents are drawn from it).
"""

from __future__ import annotations

from collections.abc import Sequence

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnvObs, VecEnvStepReturn

from iout_mj.config import Config
from iout_mj.envs.batch import MissionBatch
from iout_mj.envs.vec_env import MissionVecEnv, check_open, step_infos, thread_count
from iout_mj.mission import OBS_HIGH, OBS_LOW
from iout_mj.mission.tokens import K_MAX, token_size


def token_spaces(cfg: Config) -> tuple[gym.spaces.Box, gym.spaces.MultiDiscrete]:
    """Observation and action space of a general policy for the config's N and motion."""
    n, m = cfg.scenario.n_auvs, cfg.motion
    observation = gym.spaces.Box(OBS_LOW, OBS_HIGH, shape=(token_size(n),), dtype=np.float32)
    return observation, gym.spaces.MultiDiscrete(
        [m.heading_levels, m.speed_levels, K_MAX, K_MAX] * n
    )


class ScenarioVecEnv(MissionVecEnv):
    """B environments spread over scenario cells, random layouts.

    Args:
        cells: (K, config) of every cell; the configs share N and the action mapping.
        envs_per_cell: environments of each cell.
        backend: "kinematic" or "mujoco".
        seed: seeds the one RNG of all cells.
        nthread: C threads of each cell's MuJoCo rollout (0 to the CPUs this process may
            use).
    """

    def __init__(
        self,
        cells: Sequence[tuple[int, Config]],
        envs_per_cell: int = 1,
        backend: str = "kinematic",
        seed: int | None = None,
        nthread: int = 0,
    ):
        if not cells:
            raise ValueError("cells: accepted a non-empty list of (n_nodes, config)")
        n_auvs = cells[0][1].scenario.n_auvs
        nthread = thread_count(nthread)
        self.batches = [
            MissionBatch(envs_per_cell, backend, n_auvs, k, "random", cfg, None, nthread, "tokens")
            for k, cfg in cells
        ]
        self.backend = backend
        self.cells = [(k, cfg) for k, cfg in cells]
        self.batch = self.batches[0]  # the RNG holder (`random`, `set_random_state`)
        self.cfg, self.mission = self.batch.cfg, self.batch.mission
        self.render_mode = None
        self.closed = False
        self._bounds = np.cumsum([0] + [b.n_envs for b in self.batches])
        gym_obs, gym_act = token_spaces(self.cfg)
        super(MissionVecEnv, self).__init__(int(self._bounds[-1]), gym_obs, gym_act)
        self.set_random_state(np.random.RandomState(seed))

    def set_random_state(self, rng: np.random.RandomState) -> None:
        """One RNG for every cell (layouts and currents are drawn from it)."""
        for b in self.batches:
            b.random = rng
        self._reset_seeds()

    def reset(self) -> VecEnvObs:
        check_open(self)
        seed = self._seeds[0]
        if seed is not None:
            self.set_random_state(np.random.RandomState(seed))
        self._reset_seeds()
        for b in self.batches:
            b.restart(None)
        return np.concatenate([b.observe() for b in self.batches])

    def step_wait(self) -> VecEnvStepReturn:
        check_open(self)
        actions = np.asarray(self._actions)
        bounds = zip(self.batches, self._bounds[:-1], strict=True)
        steps = [b.step(actions[lo : lo + b.n_envs]) for b, lo in bounds]
        return (
            np.concatenate([s.obs for s in steps]),
            np.concatenate([s.rewards for s in steps]).astype(np.float32),
            np.concatenate([s.terminated | s.truncated for s in steps]),
            [i for b, s in zip(self.batches, steps, strict=True) for i in step_infos(s, b.n_envs)],
        )

    def close(self) -> None:
        for b in self.batches:
            b.close()
        self.closed = True
