"""Named stable-baselines3 callbacks of the trainer (in the style of SB3's `callbacks`)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from iout_mj.envs.scenario_vec_env import ScenarioVecEnv
from iout_mj.envs.vec_env import MissionVecEnv
from iout_mj.mission import REWARD_TERMS
from iout_mj.mission.stats import SUMMARY_KEYS, episode_summary

CELL_EPISODE_KEYS = ("mean_aoi", "docking_rate", "jain", "delivered_bits")
"""The episode metrics logged per scenario cell (all of `SUMMARY_KEYS` over all cells)."""


class MissionLoggerCallback(BaseCallback):
    """TensorBoard at every rollout end: each reward term's mean over the rollout's steps and
    environments (`reward/<term>`), the mean summary of the episodes that ended in it
    (`episode/<key>`), the run's own fps, the training phase (`train/phase`, from 1) where
    given and, on a `ScenarioVecEnv`, the same per scenario cell (`cell/<name>/reward/<term>`,
    `cell/<name>/episode/<key>` for CELL_EPISODE_KEYS); also at the end of a phase that a
    callback stopped mid-rollout.

    Per step it adds the batch's (B, terms) array into per-cell sums (numpy) and reads the
    infos of the environments that ended; nothing is logged per step.
    """

    def __init__(self, start_timesteps: int, phase: int | None = None) -> None:
        super().__init__()
        self._t0 = time.perf_counter()
        self._n0 = start_timesteps
        self._phase = phase
        self._terms: Callable[[], np.ndarray] | None = None
        self._names: list[str] = []
        """The cells' names on a ScenarioVecEnv (else none: one group of all environments)."""
        self._starts = np.zeros(1, dtype=np.intp)
        """The first environment of every group (the cells, or all environments)."""
        self._cell_of = self._envs = np.zeros(0, dtype=np.intp)

    def _init_callback(self) -> None:
        venv = self.training_env.unwrapped
        if isinstance(venv, ScenarioVecEnv):
            self._terms = venv.term_values
            self._names = [c.name for c in venv.cells]
            self._starts = np.array([c.envs.start for c in venv.cells], dtype=np.intp)
        elif isinstance(venv, MissionVecEnv):
            mission = venv.mission
            self._terms = lambda: mission.term_values
        n_envs = self.training_env.num_envs
        self._cell_of = np.searchsorted(self._starts, np.arange(n_envs), side="right") - 1
        self._envs = np.bincount(self._cell_of, minlength=len(self._starts))
        self._clear()

    def _clear(self) -> None:
        self._sums = np.zeros((len(self._starts), len(REWARD_TERMS)))
        self._steps = 0
        self._episodes: list[list[dict[str, float]]] = [[] for _ in self._starts]

    def _on_step(self) -> bool:
        if self._terms is not None:
            self._sums += np.add.reduceat(self._terms(), self._starts, axis=0)
            self._steps += 1
        infos = self.locals["infos"]
        for e in np.flatnonzero(self.locals["dones"]):
            if "metrics" in infos[e]:
                self._episodes[self._cell_of[e]].append(episode_summary(infos[e]["metrics"]))
        return True

    def _on_rollout_end(self) -> None:
        self._record()

    def _on_training_end(self) -> None:
        """A phase stopped by a callback ends inside its last rollout, which SB3 then neither
        ends nor logs: log it here."""
        if self._steps:
            self._record()
            self.logger.dump(self.num_timesteps)

    def _record(self) -> None:
        if self._steps:
            cells = self._sums / (self._steps * self._envs[:, None])
            overall = self._sums.sum(axis=0) / (self._steps * self._envs.sum())
            for t, term in enumerate(REWARD_TERMS):
                self.logger.record(f"reward/{term}", float(overall[t]))
                for c, name in enumerate(self._names):
                    self.logger.record(f"cell/{name}/reward/{term}", float(cells[c, t]))
        every = [row for rows in self._episodes for row in rows]
        for key in SUMMARY_KEYS if every else ():
            self.logger.record(f"episode/{key}", float(np.mean([r[key] for r in every])))
        for c, name in enumerate(self._names):
            rows = self._episodes[c]
            for key in CELL_EPISODE_KEYS if rows else ():
                value = float(np.mean([r[key] for r in rows]))
                self.logger.record(f"cell/{name}/episode/{key}", value)
        dt = time.perf_counter() - self._t0
        self.logger.record("time/fps_run", (self.model.num_timesteps - self._n0) / max(dt, 1e-9))
        if self._phase is not None:
            self.logger.record("train/phase", self._phase)
        self._clear()


class EvalCheckpointCallback(BaseCallback):
    """At the first rollout start after every `every_steps` steps, `checkpoint(model)`
    evaluates and saves (between an update and the next collection, so weights, optimizer and
    RNGs are consistent); stops the phase at `phase_end`; `progress(num_timesteps)` after
    every step."""

    def __init__(
        self,
        every_steps: int,
        phase_end: int,
        start_timesteps: int,
        checkpoint: Callable[[Any], None],
        progress: Callable[[int], None],
    ) -> None:
        super().__init__()
        self.every_steps, self.phase_end = every_steps, phase_end
        self.last_eval = start_timesteps
        self.checkpoint, self.progress = checkpoint, progress

    def _on_rollout_start(self) -> None:
        if self.model.num_timesteps - self.last_eval >= self.every_steps:
            self.last_eval = self.model.num_timesteps
            self.checkpoint(self.model)

    def _on_step(self) -> bool:
        self.progress(self.model.num_timesteps)
        return self.model.num_timesteps < self.phase_end
