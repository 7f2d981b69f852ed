"""Named stable-baselines3 callbacks of the trainer (in the style of SB3's `callbacks`)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from iout_mj.mission.stats import episode_summary


class MissionLoggerCallback(BaseCallback):
    """TensorBoard: every reward term, the episode metrics and the run's own fps."""

    def __init__(self, start_timesteps: int) -> None:
        super().__init__()
        self._t0 = time.perf_counter()
        self._n0 = start_timesteps

    def _on_step(self) -> bool:
        mission = getattr(self.training_env.unwrapped, "mission", None)  # the batched VecEnvs
        if mission is not None:
            for k, v in mission.terms.items():
                self.logger.record_mean(f"reward/{k}", float(np.mean(v)))
        for info in self.locals["infos"]:
            for k, v in info.get("reward_terms", {}).items():
                self.logger.record_mean(f"reward/{k}", v)
            if "metrics" in info:
                for k, v in episode_summary(info["metrics"]).items():
                    self.logger.record_mean(f"episode/{k}", v)
        return True

    def _on_rollout_end(self) -> None:
        dt = time.perf_counter() - self._t0
        self.logger.record("time/fps_run", (self.model.num_timesteps - self._n0) / max(dt, 1e-9))


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
