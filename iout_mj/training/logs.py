"""What a training run shows: the console (a progress bar through imitation and through each
phase, one line per held-out evaluation) and its TensorBoard log (the config, the
hyperparameters, phase markers, and one step axis across `--resume`)."""

from __future__ import annotations

import re
import time
from pathlib import Path
from typing import Any

import yaml
from stable_baselines3.common.logger import HParam, Logger, TensorBoardOutputFormat
from tensorboard.compat.proto.event_pb2 import Event, SessionLog
from tqdm import tqdm

from iout_mj.training.config import TrainConfig

EVAL_METRICS = ("return", "mean_aoi_horizon", "docking_rate", "jain")
"""The evaluation metrics of the console line and of TensorBoard's hparams view."""


def phase_label(cfg: TrainConfig, index: int) -> str:
    """Phase `index` (from 0) as a reader counts it: "1/2 kinematic"."""
    return f"{index + 1}/{len(cfg.phases)} {cfg.phases[index].backend}"


def eval_line(entry: dict[str, Any], new_best: bool) -> str:
    """One held-out evaluation (a history entry) as a console line."""
    return (
        f"eval {entry['num_timesteps']:>11,} steps  phase {entry['phase']}/{entry['phases']} "
        f"{entry['backend']:<9}  return {entry['return']:9.2f}  "
        f"mean AoI over T_max {entry['mean_aoi_horizon']:7.2f} slots  "
        f"docking {entry['docking_rate']:4.0%}  Jain {entry['jain']:.3f}"
        + ("  new best" if new_best else "")
    )


class Console:
    """The step bar of the PPO phases (created when the first phase starts, so that it does
    not stand at 0 through the imitation) and printed lines; silent unless `enabled`."""

    def __init__(self, cfg: TrainConfig, enabled: bool) -> None:
        self.cfg, self.enabled = cfg, enabled
        self._bar: Any = None

    def phase(self, index: int, num_timesteps: int) -> None:
        """Phase `index` starts (or resumes) at `num_timesteps`."""
        if self._bar is None:
            self._bar = tqdm(
                total=self.cfg.total_timesteps,
                initial=num_timesteps,
                unit="step",
                disable=not self.enabled,
            )
        self._bar.set_description(f"{self.cfg.name} phase {phase_label(self.cfg, index)}", False)

    def steps(self, num_timesteps: int) -> None:
        if self._bar is not None:
            self._bar.update(num_timesteps - self._bar.n)

    def line(self, text: str) -> None:
        if self.enabled:
            tqdm.write(text)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()


def run_logger(folder: Path, start_step: int) -> Logger:
    """SB3's logger of a run, TensorBoard events in `folder` on one step axis across resumes.

    The event file opens with TensorBoard's (re)start marker at `start_step`: 0 for a new run,
    T + 1 for a run resumed from its checkpoint at step T. TensorBoard then hides what a killed
    run logged after T (the resumed run logs those steps again) and keeps what it logged up to
    T, which is the same as the uninterrupted run's. The trainer logs an evaluation before it
    saves the checkpoint, so a kill between the two leaves nothing missing.
    """
    _wait_for_a_later_second(folder)
    output = TensorBoardOutputFormat(str(folder))
    marker = Event(step=start_step, session_log=SessionLog(status=SessionLog.START))
    writer = output.writer.file_writer
    assert writer is not None  # open until the logger closes
    writer.add_event(marker)
    return Logger(str(folder), [output])


def _wait_for_a_later_second(folder: Path) -> None:
    """Until the clock's second is none of the event files' in `folder`. TensorBoard reads a
    folder's event files in name order, and a name is "events.out.tfevents.<second>.<host>.
    <pid>.<counter>": within one second the pid and the counter, compared as text, may put a
    resumed run's file before the crashed run's, whose restart marker then hides the resumed
    run's steps (seen in the tests, where both run in one process within a second)."""
    names = (re.match(r"events\.out\.tfevents\.(\d+)\.", f.name) for f in folder.glob("*"))
    seconds = {int(m.group(1)) for m in names if m}
    while int(time.time()) in seconds:  # at most a second (a file from a skewed clock: none)
        time.sleep(0.05)


def _markdown_code(text: str) -> str:
    return "\n".join("    " + line for line in text.splitlines())


def hyperparameters(cfg: TrainConfig) -> dict[str, Any]:
    """The run's hyperparameters as TensorBoard's hparams take them (numbers, strings,
    booleans): every training-config entry but the env config, and the scenario's N and K."""
    spec = cfg.env_spec
    out: dict[str, Any] = {"n_auvs": spec.n_auvs, "n_nodes": spec.n_nodes}
    for key, value in cfg.to_dict().items():
        if key in ("env", "n_auvs", "n_nodes"):
            continue
        if key == "phases":
            value = ", ".join(f"{p['backend']} {p['timesteps']}" for p in value)
        out[key] = value if isinstance(value, int | float | str | bool) else str(value)
    out["total_timesteps"] = cfg.total_timesteps
    return out


def log_run_start(logger: Logger, cfg: TrainConfig) -> None:
    """At step 0 of a new run: its whole config (YAML) and hyperparameters as text, and the
    hyperparameters for TensorBoard's hparams view (against the evaluation metrics)."""
    params = hyperparameters(cfg)
    config = yaml.safe_dump(cfg.to_dict(), sort_keys=False)
    table = "| hyperparameter | value |\n|---|---|\n" + "\n".join(
        f"| {k} | {v} |" for k, v in params.items()
    )
    logger.record("run/config", _markdown_code(config))
    logger.record("run/hyperparameters", table)
    metrics = {f"eval/{k}": 0.0 for k in EVAL_METRICS}
    logger.record("hparams", HParam(params, metrics))
    logger.dump(0)


def record_phase_start(logger: Logger, cfg: TrainConfig, index: int, start_steps: int) -> None:
    """The text marker of a phase's start (written with the phase's first rollout; the phase
    number itself is the scalar `train/phase` of every rollout)."""
    end = sum(p.timesteps for p in cfg.phases[: index + 1])
    text = f"phase {phase_label(cfg, index)}: from step {start_steps:,} to {end:,}"
    logger.record("run/phase", text)
