"""An SB3 VecEnv over a distribution of scenarios: one `MissionBatch` per cell (a number of
nodes K and an env config, e.g. a noise model), token observations padded to K_MAX and one
action space `MultiDiscrete([H, S, K_MAX, K_MAX] * N)`, so that one policy trains on all
cells at once. Each cell draws its layouts and currents from its own stream, seeded from the
VecEnv's RNG, so a cell steps exactly as its batch would alone (`ScenarioCell.batch`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import (
    VecEnvObs,
    VecEnvStepReturn,
)

from iout_mj.config import Config
from iout_mj.envs.batch import MissionBatch, rng_arrays, set_rng
from iout_mj.envs.vec_env import (
    BatchedVecEnv,
    batch_state_arrays,
    check_open,
    load_batch_state_arrays,
    step_infos,
    thread_count,
)
from iout_mj.mission import OBS_HIGH, OBS_LOW
from iout_mj.mission.tokens import K_MAX, token_size
from iout_mj.schema import ConfigError


def token_spaces(cfg: Config) -> tuple[gym.spaces.Box, gym.spaces.MultiDiscrete]:
    """Observation and action space of a general policy for the config's N and motion."""
    n, m = cfg.scenario.n_auvs, cfg.motion
    observation = gym.spaces.Box(OBS_LOW, OBS_HIGH, shape=(token_size(n),), dtype=np.float32)
    return observation, gym.spaces.MultiDiscrete(
        [m.heading_levels, m.speed_levels, K_MAX, K_MAX] * n
    )


@dataclass(frozen=True)
class ScenarioCell:
    """One scenario cell of a `ScenarioVecEnv` and the batch that steps its environments."""

    name: str
    """`k{K}_{noise model}` (a suffix `_{index}` where two cells would share it): the
    TensorBoard prefix `cell/<name>/` of its reward terms and episode metrics."""
    n_nodes: int
    config: Config
    batch: MissionBatch
    envs: slice
    """Its environments' indices in the VecEnv (observations, rewards, infos)."""

    @property
    def noise_model(self) -> str:
        return self.config.acoustics.noise_model


def _cell_names(cells: Sequence[tuple[int, Config]]) -> list[str]:
    names = [f"k{k}_{cfg.acoustics.noise_model}" for k, cfg in cells]
    return [f"{n}_{i}" if names.count(n) > 1 else n for i, n in enumerate(names)]


def _check_shared(cells: Sequence[tuple[int, Config]]) -> None:
    """Every cell has the first cell's N and action mapping (one policy acts in all)."""
    if not cells:
        raise ValueError("cells=[]: accepted a non-empty list of (n_nodes, config)")

    def shared(cfg: Config) -> dict[str, int]:
        m = cfg.motion
        return {
            "n_auvs": cfg.scenario.n_auvs,
            "heading_levels": m.heading_levels,
            "speed_levels": m.speed_levels,
        }

    first = shared(cells[0][1])
    for i, (k, cfg) in enumerate(cells):
        if shared(cfg) != first:
            raise ConfigError(
                f"cells[{i}] (K={k}) has {shared(cfg)}; accepted the first cell's {first}: one "
                "policy acts in every cell"
            )


class ScenarioVecEnv(BatchedVecEnv):
    """B environments spread over scenario cells, random layouts.

    Args:
        cells: (K, config) of every cell; the configs share N and the action mapping.
        envs_per_cell: environments of each cell.
        backend: "kinematic", "mujoco" or "warp".
        seed: seeds the RNG that seeds every cell's stream (`set_random_state`).
        nthread: threads that step the cells of a MuJoCo backend concurrently (each cell's
            rollout releases the GIL; 0 or 1: in turn on the calling thread; at most the CPUs
            this process may use). Every cell steps exactly as it would alone.

    `cells` holds each cell's K, config, batch and environment indices; `term_values()` the
    last step's reward terms of all environments. Stepping or resetting after `close()`
    raises `RuntimeError`.
    """

    _envs_live_in = "venv.cells[c].batch"

    def __init__(
        self,
        cells: Sequence[tuple[int, Config]],
        envs_per_cell: int = 1,
        backend: str = "kinematic",
        seed: int | None = None,
        nthread: int = 0,
    ):
        _check_shared(cells)
        n_auvs, nthread = cells[0][1].scenario.n_auvs, thread_count(nthread)
        self.cells: list[ScenarioCell] = []
        for i, ((k, cfg), name) in enumerate(zip(cells, _cell_names(cells), strict=True)):
            batch = MissionBatch(
                envs_per_cell, backend, n_auvs, k, "random", cfg, None, 0, "tokens"
            )
            envs = slice(i * batch.n_envs, (i + 1) * batch.n_envs)
            self.cells.append(ScenarioCell(name, k, cfg, batch, envs))
        self.backend = backend
        self._pool = (
            ThreadPoolExecutor(nthread, thread_name_prefix="cells")
            if nthread > 1 and backend != "kinematic"
            else None
        )
        self.cfg = self.cells[0].config
        """The first cell's config (N and the action mapping are every cell's)."""
        self.render_mode = None
        self.closed = False
        self.random = np.random.RandomState(seed)
        self.cell_seeds: tuple[int, ...] = ()
        super().__init__(self.cells[-1].envs.stop, *token_spaces(self.cfg))
        self.set_random_state(self.random)

    def set_random_state(self, rng: np.random.RandomState) -> None:
        """Seed every cell's stream from `rng` (one draw per cell, in order: `cell_seeds`),
        dropping any seed given with `seed()` that the next `reset()` would otherwise apply."""
        self.random = rng
        self.cell_seeds = tuple(int(s) for s in rng.randint(2**32, size=len(self.cells)))
        for cell, seed in zip(self.cells, self.cell_seeds, strict=True):
            cell.batch.random = np.random.RandomState(seed)
        self._reset_seeds()

    def term_values(self) -> np.ndarray:
        """The last step's reward terms, (B, terms) in the order of REWARD_TERMS (a copy)."""
        return np.concatenate([c.batch.mission.term_values for c in self.cells])

    def state_arrays(self) -> dict[str, np.ndarray]:
        """Copies of everything that changes as the env steps: every cell's batch state, its
        stream included (keyed '<cell index>.<name>', `MissionBatch.state_arrays`), the RNG
        that seeds the cells (`random.*`) and `cell_seeds`; all a resumed run needs."""
        out = batch_state_arrays([c.batch for c in self.cells])
        out.update({f"random.{k}": v for k, v in rng_arrays(self.random).items()})
        out["cell_seeds"] = np.array(self.cell_seeds, dtype=np.int64)
        return out

    def load_state_arrays(self, arrays: Mapping[str, np.ndarray]) -> None:
        """Put back `state_arrays()` of a ScenarioVecEnv of the same cells and sizes, dropping
        any seed given with `seed()`; raises ValueError naming what does not fit."""
        cells = dict(arrays)
        try:
            seeds = np.asarray(cells.pop("cell_seeds"))
            rng = {k: cells.pop(f"random.{k}") for k in ("key", "pos", "gauss")}
        except KeyError as exc:
            raise ValueError(
                f"saved env state lacks {exc}: accepted ScenarioVecEnv.state_arrays()"
            ) from exc
        if seeds.shape != (len(self.cells),):
            raise ValueError(
                f"saved cell_seeds of shape {seeds.shape}; accepted ({len(self.cells)},)"
            )
        load_batch_state_arrays([c.batch for c in self.cells], cells)
        set_rng(self.random, rng)
        self.cell_seeds = tuple(int(s) for s in seeds)
        self._reset_seeds()

    # ------------------------------------------------------------------ VecEnv
    def reset(self) -> VecEnvObs:
        check_open(self)
        seed = self._seeds[0]
        if seed is not None:
            self.set_random_state(np.random.RandomState(seed))
        self._reset_seeds()
        for c in self.cells:
            c.batch.restart(None)
        return np.concatenate([c.batch.observe() for c in self.cells])

    def step_async(self, actions: np.ndarray) -> None:
        check_open(self)
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        check_open(self)
        actions = np.asarray(self._actions)
        if self._pool is None:
            steps = [c.batch.step(actions[c.envs]) for c in self.cells]
        else:
            steps = list(self._pool.map(lambda c: c.batch.step(actions[c.envs]), self.cells))
        infos = [
            i for c, s in zip(self.cells, steps, strict=True) for i in step_infos(s, c.batch.n_envs)
        ]
        return (
            np.concatenate([s.obs for s in steps]),
            np.concatenate([s.rewards for s in steps]).astype(np.float32),
            np.concatenate([s.terminated | s.truncated for s in steps]),
            infos,
        )

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()
        for c in self.cells:
            c.batch.close()
        self.closed = True
