"""Both backends as stable-baselines3 `VecEnv`s: B environments in one batched `Mission`.

One `step` call moves all B environments (the same mission, network and reward code as the
gymnasium env) with no Python loop over environments except the info dicts of the ones that
finish:

- `KinematicVecEnv`: the paper's kinematics on the batch (`backends.kinematic.move`), one core.
- `PhysicsVecEnv`: B MuJoCo scenes stepped by one `mujoco.rollout` call, whose C threads
  (`nthread`) share the slot's substeps between cores: no worker processes, no pickling.

Finished environments restart at once (SB3 convention): their `info` holds
`terminal_observation`, `TimeLimit.truncated` and `metrics` (and `error` if the physics
diverged); wrap in SB3's `VecMonitor` for episode returns. The reward terms of the last step
are `venv.mission.terms` (arrays of B), not per-step infos.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import (
    VecEnv,
    VecEnvIndices,
    VecEnvObs,
    VecEnvStepReturn,
)

from iout_mj.backends.kinematic import move
from iout_mj.backends.mujoco.physics import AUVPhysics, Stepper
from iout_mj.backends.mujoco.task import book, command, start_episode, substeps_per_slot
from iout_mj.envs.gym_env import spaces
from iout_mj.mission import Mission
from iout_mj.scenarios import ConfigLike, resolve_config
from iout_mj.types import BoolArray, FloatArray


class MissionVecEnv(VecEnv):
    """A batched Mission behind the VecEnv interface; subclasses move the vehicles.

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
        config: ConfigLike = None,
        seed: int | None = None,
    ):
        if not isinstance(n_envs, (int, np.integer)) or n_envs < 1:
            raise ValueError(f"n_envs={n_envs!r} is invalid: accepted an integer >= 1")
        self.cfg = resolve_config(config, n_auvs, n_nodes, layout)
        self.mission = Mission(self.cfg, layout == "random", n_envs=int(n_envs))
        self.random = np.random.RandomState(seed)
        self.render_mode = None
        super().__init__(int(n_envs), *spaces(self.mission))
        self._actions: Any = None
        self._none_failed = np.zeros(self.num_envs, dtype=bool)

    def set_random_state(self, rng: np.random.RandomState) -> None:
        """Continue the batch's random stream from `rng` (a resumed run), dropping any seed
        given with `seed()` that the next `reset()` would otherwise apply."""
        self.random = rng
        self._reset_seeds()

    # ------------------------------------------------------------------ subclass hooks
    def _move(self, actions: Any) -> tuple[FloatArray, BoolArray]:
        """One slot for every environment: rewards, and which envs failed (diverged)."""
        raise NotImplementedError

    def _restart(self, mask: BoolArray | None) -> None:
        """Start new episodes where `mask` (everywhere for None)."""
        self.mission.reset(self.random, mask)

    # ------------------------------------------------------------------ VecEnv
    def reset(self) -> VecEnvObs:
        seed = self._seeds[0]
        if seed is not None:
            self.random = np.random.RandomState(seed)
        self._reset_seeds()
        self._restart(None)
        return self.mission.flat_observation()

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        m = self.mission
        rewards, failed = self._move(self._actions)
        obs = m.flat_observation()
        terminated = m.state.terminated | failed
        done = terminated | m.state.truncated
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if done.any():
            for e in np.flatnonzero(done):
                infos[e] = {
                    "terminal_observation": obs[e].copy(),
                    "TimeLimit.truncated": bool(not terminated[e]),
                    "metrics": m.metrics(int(e)),
                }
                if failed[e]:
                    infos[e]["error"] = "physics diverged (MuJoCo reset the state)"
                    infos[e]["terminal_observation"] = np.zeros_like(obs[e])
            self._restart(done)
            obs[done] = m.flat_observation()[done]
        rewards = np.where(failed, 0.0, rewards).astype(np.float32)
        return obs, rewards, done, infos

    def close(self) -> None:
        pass

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return [getattr(self, attr_name)] * len(self._get_indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        raise AttributeError(
            f"set_attr({attr_name!r}): the environments of a {type(self).__name__} share one "
            "batch and have no per-environment attributes"
        )

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **kw: Any
    ) -> list[Any]:
        raise AttributeError(
            f"env_method({method_name!r}): a {type(self).__name__} has no per-environment "
            "objects; use venv.mission"
        )

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None
    ) -> list[bool]:
        return [False] * len(self._get_indices(indices))

    def _get_indices(self, indices: VecEnvIndices) -> Sequence[int]:
        if indices is None:
            return range(self.num_envs)
        return [indices] if isinstance(indices, int) else list(indices)


class KinematicVecEnv(MissionVecEnv):
    """B kinematic environments stepped together; spaces as `iout_mj/MultiAUV-v0`."""

    def _move(self, actions: Any) -> tuple[FloatArray, BoolArray]:
        return move(self.mission, actions), self._none_failed


class PhysicsVecEnv(MissionVecEnv):
    """B MuJoCo environments stepped together; spaces as `iout_mj/MultiAUV-v0`.

    Args:
        n_envs, n_auvs, n_nodes, layout, config, seed: as for `MissionVecEnv`.
        nthread: C threads of the rollout (0: the calling thread; at most one per core helps).
    """

    def __init__(
        self,
        n_envs: int,
        n_auvs: int | None = None,
        n_nodes: int | None = None,
        layout: str = "paper",
        config: ConfigLike = None,
        seed: int | None = None,
        nthread: int = 0,
    ):
        if not isinstance(nthread, (int, np.integer)) or nthread < 0:
            raise ValueError(f"nthread={nthread!r} is invalid: accepted an integer >= 0")
        super().__init__(n_envs, n_auvs, n_nodes, layout, config, seed)
        self.physics = [AUVPhysics.from_config(self.cfg) for _ in range(self.num_envs)]
        self.substeps = substeps_per_slot(self.cfg, self.physics[0].dt_s)
        self.stepper = Stepper(nthread)

    def _restart(self, mask: BoolArray | None) -> None:
        super()._restart(mask)
        rows = range(self.num_envs) if mask is None else np.flatnonzero(mask)
        for e in rows:
            start_episode(self.mission, self.physics[e], int(e))

    def _move(self, actions: Any) -> tuple[FloatArray, BoolArray]:
        meters = command(self.mission, self.physics, actions)
        failed = self.stepper.step(self.physics, self.substeps)
        return book(self.mission, self.physics, meters), failed

    def close(self) -> None:
        self.stepper.close()
        for p in self.physics:
            p.free()
