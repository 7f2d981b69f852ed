"""Both backends as stable-baselines3 `VecEnv`s over one `MissionBatch` (`envs.batch`).

One `step` call moves all B environments (the same mission, network and reward code as the
gymnasium env) with no Python loop over environments except the info dicts of the ones that
finish. Finished environments restart at once (SB3 convention): their `info` holds
`terminal_observation`, `TimeLimit.truncated` and `metrics` (and `error` if the physics
diverged); with a channel on, every info holds `channel` as the gymnasium env's does (the
slot's per-AUV `sinr_db`, `per`, `packets_sent`, `packets_received`); wrap in SB3's
`VecMonitor` for episode returns. The reward terms of the last step
are `venv.mission.terms` (arrays of B), not per-step infos.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import (
    VecEnv,
    VecEnvIndices,
    VecEnvObs,
    VecEnvStepReturn,
)

from iout_mj.envs.batch import BatchStep, MissionBatch
from iout_mj.envs.gym_env import spaces
from iout_mj.runtime import cpu_bounded
from iout_mj.scenarios import ConfigLike


def thread_count(nthread: int) -> int:
    """`nthread` if it is from 0 (the calling thread) to the CPUs this process may use."""
    return cpu_bounded(nthread, "nthread", 0)


def check_open(venv: Any) -> None:
    """Refuse to use a closed vector env (its scenes are freed)."""
    if venv.closed:
        raise RuntimeError(f"this {type(venv).__name__} is closed: make a new one to step it")


CHANNEL_INFO = ("sinr_db", "per", "packets_sent", "packets_received")
"""The quantities of `info["channel"]` (`Mission.channel_info`), each a list over the AUVs."""


def channel_infos(channel: dict[str, np.ndarray] | None, n_envs: int) -> list[dict[str, Any]]:
    """Each environment's `{"channel": ...}` as the single env gives it (lists over AUVs), from
    the batch's (B, N) arrays: one `tolist` per quantity, no Python loop over links; empty
    dicts on the paper's channel."""
    if channel is None:
        return [{} for _ in range(n_envs)]
    sinr, per, sent, received = (channel[name].tolist() for name in CHANNEL_INFO)
    return [
        {"channel": {"sinr_db": s, "per": p, "packets_sent": n, "packets_received": r}}
        for s, p, n, r in zip(sinr, per, sent, received, strict=True)
    ]


def step_infos(step: BatchStep, n_envs: int) -> list[dict[str, Any]]:
    """SB3's info dicts of a batch step: the channel's links when a channel is on, and the end
    of an episode."""
    infos = channel_infos(step.channel, n_envs)
    for e, (final_obs, final) in step.ended.items():
        infos[e] |= {
            # a diverged scene has no meaningful last state
            "terminal_observation": np.zeros_like(final_obs) if "error" in final else final_obs,
            "TimeLimit.truncated": bool(step.truncated[e]),
            **final,
        }
    return infos


def batch_state_arrays(batches: Sequence[MissionBatch]) -> dict[str, np.ndarray]:
    """Every batch's `state_arrays`, keyed '<batch index>.<name>'."""
    return {
        f"{i}.{name}": value
        for i, batch in enumerate(batches)
        for name, value in batch.state_arrays().items()
    }


def load_batch_state_arrays(
    batches: Sequence[MissionBatch], arrays: Mapping[str, np.ndarray]
) -> None:
    """Put back `batch_state_arrays(batches)`; raises ValueError naming what does not fit."""
    per_batch: list[dict[str, np.ndarray]] = [{} for _ in batches]
    for key, value in arrays.items():
        index, _, name = key.partition(".")
        if not index.isdigit() or int(index) >= len(batches):
            raise ValueError(
                f"saved env state {key!r}: accepted '<batch index>.<name>' with an index below "
                f"{len(batches)}"
            )
        per_batch[int(index)][name] = value
    for batch, saved in zip(batches, per_batch, strict=True):
        batch.load_state_arrays(saved)


class BatchedVecEnv(VecEnv):
    """The per-environment parts of SB3's VecEnv API for environments that live in batches
    (no per-environment objects): attributes are the VecEnv's, methods refused with where the
    environments are (`_envs_live_in`)."""

    _envs_live_in = "venv.mission"

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return [getattr(self, attr_name)] * len(self._get_indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        raise AttributeError(
            f"set_attr({attr_name!r}): the environments of a {type(self).__name__} live in "
            f"batches ({self._envs_live_in}) and have no per-environment attributes"
        )

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **kw: Any
    ) -> list[Any]:
        raise AttributeError(
            f"env_method({method_name!r}): a {type(self).__name__} has no per-environment "
            f"objects; use {self._envs_live_in}"
        )

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None
    ) -> list[bool]:
        return [False] * len(self._get_indices(indices))

    def _get_indices(self, indices: VecEnvIndices) -> Sequence[int]:
        if indices is None:
            return range(self.num_envs)
        return [indices] if isinstance(indices, int) else list(indices)


class MissionVecEnv(BatchedVecEnv):
    """A `MissionBatch` behind the SB3 VecEnv interface.

    Args:
        n_envs: B, the number of environments.
        n_auvs, n_nodes, layout, config: as for `gymnasium.make("iout_mj/MultiAUV-v0", ...)`.
        seed: seeds the one RNG of the batch (also `venv.seed(s)` before `reset()`).
        nthread: C threads of the MuJoCo rollout (0: the calling thread; at most the CPUs
            this process may use, `runtime.usable_cpus()`).

    Stepping or resetting after `close()` raises `RuntimeError`.
    """

    backend = "kinematic"

    def __init__(
        self,
        n_envs: int,
        n_auvs: int | None = None,
        n_nodes: int | None = None,
        layout: str | None = None,
        config: ConfigLike = None,
        seed: int | None = None,
        nthread: int = 0,
    ):
        self.batch = MissionBatch(
            n_envs, self.backend, n_auvs, n_nodes, layout, config, seed, thread_count(nthread)
        )
        self.cfg, self.mission = self.batch.cfg, self.batch.mission
        self.render_mode = None
        self.closed = False
        super().__init__(self.batch.n_envs, *spaces(self.mission))

    @property
    def random(self) -> np.random.RandomState:
        """The one RNG of the batch."""
        return self.batch.random

    @property
    def physics(self) -> list[Any]:
        """The MuJoCo scenes (empty for the kinematic backend)."""
        return self.batch.physics

    @property
    def stepper(self) -> Any:
        return self.batch.stepper

    def set_random_state(self, rng: np.random.RandomState) -> None:
        """Continue the batch's random stream from `rng` (a resumed run), dropping any seed
        given with `seed()` that the next `reset()` would otherwise apply."""
        self.batch.random = rng
        self._reset_seeds()

    def state_arrays(self) -> dict[str, np.ndarray]:
        """Copies of everything that changes as the env steps (`MissionBatch.state_arrays`,
        its RNG included), keyed '<batch index>.<name>': all a resumed run needs to continue."""
        return batch_state_arrays([self.batch])

    def load_state_arrays(self, arrays: Mapping[str, np.ndarray]) -> None:
        """Put back `state_arrays()` of a vector env of the same config and size, dropping any
        seed given with `seed()` that the next `reset()` would otherwise apply.

        Raises:
            ValueError: the arrays do not fit this env's batches (the message says which).
        """
        load_batch_state_arrays([self.batch], arrays)
        self._reset_seeds()

    # ------------------------------------------------------------------ VecEnv
    def reset(self) -> VecEnvObs:
        check_open(self)
        seed = self._seeds[0]
        if seed is not None:
            self.batch.random = np.random.RandomState(seed)
        self._reset_seeds()
        self.batch.restart(None)
        return self.mission.flat_observation()

    def step_async(self, actions: np.ndarray) -> None:
        check_open(self)
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        check_open(self)
        step = self.batch.step(self._actions)
        done = step.terminated | step.truncated
        return step.obs, step.rewards.astype(np.float32), done, step_infos(step, self.num_envs)

    def close(self) -> None:
        self.batch.close()
        self.closed = True


class KinematicVecEnv(MissionVecEnv):
    """B kinematic environments stepped together; spaces as `iout_mj/MultiAUV-v0`."""

    backend = "kinematic"


class PhysicsVecEnv(MissionVecEnv):
    """B MuJoCo environments stepped together by one `mujoco.rollout` call per step; spaces as
    `iout_mj/MultiAUV-v0`."""

    backend = "mujoco"


class WarpVecEnv(MissionVecEnv):
    """B MuJoCo scenes stepped together by MuJoCo Warp (a GPU when there is one, else Warp's
    CPU device); spaces, rules and meters as `PhysicsVecEnv`."""

    backend = "warp"
