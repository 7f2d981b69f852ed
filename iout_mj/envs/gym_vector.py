"""The gymnasium vector API over the batched core: `gym.make_vec("iout_mj/MultiAUV-v0",
num_envs=B, vectorization_mode="vector_entry_point", backend=...)`.

One `step` moves all B environments (`envs.batch.MissionBatch`), as the SB3 VecEnvs do.
Autoreset is gymnasium's same-step mode (`metadata["autoreset_mode"]`): an environment that
ends is reset in the same step, the returned observation is its new episode's first, and
`info["final_obs"]` / `info["final_info"]` (masked by `info["_final_obs"]`) hold the end of
the old one, `final_info` with the episode's `metrics`. Every step's `info["reward_terms"]`
holds each reward term for every environment; with a channel on, `info["channel"]` holds the
slot's per-AUV links as (B, N) arrays (`sinr_db`, `per`, `packets_sent`, `packets_received`;
row e is environment e's `info["channel"]` of the gymnasium env).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from iout_mj.envs.batch import MissionBatch
from iout_mj.envs.gym_env import spaces
from iout_mj.errors import require_seed
from iout_mj.runtime import cpu_bounded
from iout_mj.scenarios import ConfigLike


class MultiAUVVectorEnv(VectorEnv):
    """B multi-AUV environments in one batch; the spaces of `iout_mj/MultiAUV-v0`, batched.

    Args:
        num_envs: B.
        n_auvs, n_nodes, backend, layout, config: as for `gymnasium.make`.
        nthread: C threads of the MuJoCo rollout (0: the calling thread; at most the CPUs
            this process may use).
        render_mode: None (rendering is per env: use `gymnasium.make`).

    Stepping or resetting after `close()` raises `RuntimeError`.
    """

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}  # noqa: RUF012

    def __init__(
        self,
        num_envs: int,
        n_auvs: int | None = None,
        n_nodes: int | None = None,
        backend: str = "kinematic",
        layout: str | None = None,
        config: ConfigLike = None,
        nthread: int = 0,
        render_mode: str | None = None,
    ):
        if render_mode is not None:
            raise ValueError(
                f"render_mode={render_mode!r}: the vector env does not render; accepted None"
            )
        nthread = cpu_bounded(nthread, "nthread", 0)
        self.batch = MissionBatch(num_envs, backend, n_auvs, n_nodes, layout, config, None, nthread)
        self.mission = self.batch.mission
        self.num_envs = self.batch.n_envs
        self.single_observation_space, self.single_action_space = spaces(self.mission)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.render_mode = None
        self._needs_reset = True

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start every environment; `seed` (an int) seeds the batch's one RNG."""
        self._check_open()
        if isinstance(seed, list):
            raise ValueError(
                "seed: accepted one integer for the whole batch (it draws every environment's "
                "episode from one RNG), or None"
            )
        if require_seed(seed, allow_none=True) is not None:
            self.batch.random = np.random.RandomState(seed)
        self.batch.restart(None)
        self._needs_reset = False
        return self.mission.flat_observation(), {}

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        self._check_open()
        if self._needs_reset:
            raise RuntimeError("step() before reset(): call reset() first")
        step = self.batch.step(actions)
        infos: dict[str, Any] = {
            "reward_terms": {
                k: np.broadcast_to(v, (self.num_envs,)).astype(float)
                for k, v in self.mission.terms.items()
            },
            "_reward_terms": np.ones(self.num_envs, dtype=bool),
        }
        if step.channel is not None:
            infos["channel"] = step.channel
            infos["_channel"] = np.ones(self.num_envs, dtype=bool)
        for e, (final_obs, final) in step.ended.items():
            infos = self._add_info(infos, {"final_obs": final_obs, "final_info": final}, e)
        return step.obs, step.rewards, step.terminated, step.truncated, infos

    def _check_open(self) -> None:
        if self.closed:
            raise RuntimeError(f"this {type(self).__name__} is closed: make a new one to step it")

    def close_extras(self, **kwargs: Any) -> None:
        self.batch.close()
