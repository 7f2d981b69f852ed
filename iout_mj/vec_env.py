"""The kinematic backend as a stable-baselines3 `VecEnv`: B environments in one numpy batch.

One `step` call moves all B environments with `kinematic.move` on a batched `Mission` (the
same mission, network and reward code as every other backend), on one core, with no Python
loop over environments except the info dicts of the ones that finish. Finished environments
restart at once (SB3 convention): their `info` holds `terminal_observation`,
`TimeLimit.truncated` and `metrics` (wrap in SB3's `VecMonitor` for episode returns); the
reward terms of the last step are `venv.mission.terms` (arrays of B), not per-step infos.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import (
    VecEnv,
    VecEnvIndices,
    VecEnvObs,
    VecEnvStepReturn,
)

from iout_mj.config import Config
from iout_mj.envs import resolve_config
from iout_mj.kinematic import move
from iout_mj.mission import OBS_HIGH, OBS_LOW, Mission


class KinematicVecEnv(VecEnv):
    """B kinematic environments stepped together; spaces as `iout_mj/MultiAUV-v0`.

    Args:
        n_envs: B, the number of environments.
        n_auvs, n_nodes, layout, config: as for `gymnasium.make("iout_mj/MultiAUV-v0", ...)`.
        seed: seeds the one RNG of the batch (also `venv.seed(s)` before `reset()`).
    """

    def __init__(
        self,
        n_envs: int,
        n_auvs: int | None = None,
        n_nodes: int | None = None,
        layout: str = "paper",
        config: Config | dict[str, Any] | str | Path | None = None,
        seed: int | None = None,
    ):
        if not isinstance(n_envs, (int, np.integer)) or n_envs < 1:
            raise ValueError(f"n_envs={n_envs!r} is invalid: accepted an integer >= 1")
        self.cfg = resolve_config(config, n_auvs, n_nodes, layout)
        self.mission = Mission(self.cfg, layout == "random", n_envs=int(n_envs))
        self.random = np.random.RandomState(seed)
        self.render_mode = None
        size = sum(self.mission.observation_sizes().values())
        super().__init__(
            int(n_envs),
            gym.spaces.Box(OBS_LOW, OBS_HIGH, shape=(size,), dtype=np.float32),
            gym.spaces.MultiDiscrete(self.mission.action_high.copy()),
        )
        self._actions: Any = None

    def reset(self) -> VecEnvObs:
        seed = self._seeds[0]
        if seed is not None:
            self.random = np.random.RandomState(seed)
        self._reset_seeds()
        self.mission.reset(self.random)
        return self.mission.flat_observation()

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        m = self.mission
        rewards = move(m, self._actions).astype(np.float32)
        obs = m.flat_observation()
        terminated = m.terminated
        done = terminated | m.truncated
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if done.any():
            for e in np.flatnonzero(done):
                infos[e] = {
                    "terminal_observation": obs[e].copy(),
                    "TimeLimit.truncated": bool(not terminated[e]),
                    "metrics": m.metrics(int(e)),
                }
            m.reset(self.random, done)
            obs[done] = m.flat_observation()[done]
        return obs, rewards, done, infos

    def close(self) -> None:
        pass

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return [getattr(self, attr_name)] * len(self._get_indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        raise AttributeError(
            f"set_attr({attr_name!r}): the environments of a KinematicVecEnv share one batch "
            "and have no per-environment attributes"
        )

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **kw: Any
    ) -> list[Any]:
        raise AttributeError(
            f"env_method({method_name!r}): a KinematicVecEnv has no per-environment objects; "
            "use venv.mission"
        )

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None
    ) -> list[bool]:
        return [False] * len(self._get_indices(indices))

    def _get_indices(self, indices: VecEnvIndices) -> Sequence[int]:
        if indices is None:
            return range(self.num_envs)
        return [indices] if isinstance(indices, int) else list(indices)
