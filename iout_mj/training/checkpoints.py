"""Run folders: checkpoints in the safe policy format, replaced whole or not at all.

A run folder holds `config.yaml` (the exact training config), `last/` and `best/` (policy
folders, `agents.policy_format`, whose manifests also hold the run state, so a checkpoint is
self-describing), `state.json` (a copy of the last run state, for people and figures) and
TensorBoard logs under `tb/`. A training checkpoint adds the optimizer state and the global
RNGs (torch, numpy's that SB3's minibatches draw from, python's) to the weights file, so
`--resume` continues the schedule, the statistics and the random streams. A checkpoint taken
inside a phase (`live`) also holds the running episodes: the environments' whole state
(`MissionVecEnv.state_arrays`: mission, nodes, log, their RNGs, MuJoCo scenes and energy
meters), the per-environment discounted returns of the reward normalisation, the monitor's
episode counters, and SB3's last observation and episode starts. A run killed at any moment
and resumed from its last checkpoint thus equals the uninterrupted run bit for bit (a new
phase's environments start from their seed, as in the uninterrupted run). These arrays are
stored as their raw bits (floats and unsigned integers as signed integers of the same size):
exact, and the environments' state legitimately holds infinities (no separation measured yet)
that the weights file's finiteness check refuses in float tensors.

Every file of a checkpoint is covered by a checksum (`policy_format`): an edited run state is
refused on resume with the file's name, not trained on. A write is whole or not at all; a
fault (no space left, file too large) raises one `CheckpointError` with the OS's reason and
leaves the previous checkpoint and no temporary folder; after a kill, `recover` keeps the
complete checkpoint, old or new, and removes the partial one.
"""

from __future__ import annotations

import ast
import json
import math
import os
import random
import stat
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3.common.vec_env import VecMonitor, unwrap_vec_wrapper

from iout_mj.agents.policy_format import (
    build_policy,
    normalization_dict,
    read_manifest,
    read_normalization,
    read_tensors,
    save_policy,
)
from iout_mj.errors import CheckpointError, PolicyError
from iout_mj.files import remove, write_atomic
from iout_mj.training.config import TrainConfig


@dataclass
class RunState:
    """Where a run stands: in every checkpoint's manifest, and copied to `state.json`."""

    phase: int = 0
    num_timesteps: int = 0
    best_score: float = -1e300
    history: list[dict[str, Any]] = field(default_factory=list)

    def save(self, path: Path) -> None:
        """The copy for people and figures, replaced whole; a fault raises `CheckpointError`."""
        try:
            write_atomic(path, (json.dumps(asdict(self), indent=1) + "\n").encode())
        except OSError as exc:
            raise CheckpointError(f"cannot write {path}: {exc.strerror or exc}") from exc


def _count(value: Any, name: str, high: float = math.inf) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= high:
        raise ValueError(f"{name} is {value!r:.60}; accepted an integer in [0, {high}]")
    return value


def _run_state(manifest: dict[str, Any], cfg: TrainConfig | None = None) -> RunState:
    """The manifest's run state, checked (and against the run's config when given)."""
    raw = manifest.get("run_state")
    if not isinstance(raw, dict) or set(raw) != {"phase", "num_timesteps", "best_score", "history"}:
        raise ValueError("run_state must hold phase, num_timesteps, best_score and history")
    phases = len(cfg.phases) if cfg else math.inf
    # a phase ends at its step count or within the rollout that crosses it
    steps = cfg.total_timesteps + cfg.n_steps * cfg.n_envs if cfg else math.inf
    best = raw["best_score"]
    if not isinstance(best, int | float) or isinstance(best, bool) or not math.isfinite(best):
        raise ValueError(f"run_state.best_score is {best!r:.60}; accepted a finite number")
    history = raw["history"]
    if not isinstance(history, list) or not all(isinstance(h, dict) for h in history):
        raise ValueError("run_state.history must be a list of evaluation entries")
    return RunState(
        _count(raw["phase"], "run_state.phase", phases),
        _count(raw["num_timesteps"], "run_state.num_timesteps", steps),
        float(best),
        history,
    )


def read_run_state(folder: Path, cfg: TrainConfig) -> RunState:
    """The run state of a checkpoint to resume with `cfg`, checked (phase and steps within the
    config's); raises `CheckpointError` saying what is wrong."""
    try:
        return _run_state(read_manifest(folder), cfg)
    except (PolicyError, ValueError) as exc:
        raise CheckpointError(f"cannot resume from {folder}: {exc}") from exc


def _rng_tensors() -> tuple[dict[str, torch.Tensor], Any]:
    """The global RNGs' states: tensors for the weights file, the rest as JSON."""
    global_state: Any = np.random.get_state()
    np_key, np_pos, np_gauss, np_cached = global_state[1:]
    tensors = {
        "rng.torch": torch.get_rng_state(),
        "rng.numpy_key": torch.from_numpy(np.asarray(np_key, dtype=np.int64)),
    }
    scalars = {
        "numpy": [int(np_pos), int(np_gauss), float(np_cached)],
        "python": repr(random.getstate()),
    }
    return tensors, scalars


def _restore_rngs(tensors: dict[str, torch.Tensor], scalars: dict[str, Any]) -> None:
    torch.set_rng_state(tensors["rng.torch"])
    pos, gauss, cached = scalars["numpy"]
    key = tensors["rng.numpy_key"].numpy().astype(np.uint32)
    np.random.set_state(("MT19937", key, pos, gauss, cached))


def _bits(array: np.ndarray) -> torch.Tensor:
    """An array as a tensor of its raw bits (floats and unsigned integers as signed integers
    of the same size)."""
    a = np.ascontiguousarray(array)
    if a.dtype.kind in "fu":
        a = a.view(np.dtype(f"i{a.itemsize}"))
    return torch.from_numpy(a.copy())


def _unbits(tensor: torch.Tensor, like: np.ndarray) -> np.ndarray:
    """The array of `_bits`, as the dtype of `like` (a mismatch is left for the caller's
    shape and dtype check)."""
    a = tensor.numpy()
    if like.dtype.kind in "fu" and a.dtype == np.dtype(f"i{like.dtype.itemsize}"):
        a = a.view(like.dtype)
    return a


def _monitor(venv: Any) -> VecMonitor:
    """The VecMonitor under the trainer's VecNormalize."""
    monitor = unwrap_vec_wrapper(venv, VecMonitor)
    assert isinstance(monitor, VecMonitor), "the trainer's environments are monitored"
    return monitor


def _live_tensors(model: Any) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
    """The running episodes (see the module's docstring): tensors, and the rest as JSON."""
    venv = model.get_vec_normalize_env()
    monitor = _monitor(venv)
    tensors = {f"env.{k}": _bits(v) for k, v in venv.unwrapped.state_arrays().items()}
    tensors.update(
        {
            "run.last_obs": _bits(model._last_obs),
            "run.episode_starts": _bits(model._last_episode_starts),
            "run.original_obs": _bits(venv.old_obs),
            "run.returns": _bits(venv.returns),
            "run.monitor_returns": _bits(monitor.episode_returns),
            "run.monitor_lengths": _bits(monitor.episode_lengths),
        }
    )
    return tensors, {"monitor_episode_count": int(monitor.episode_count)}


def save_checkpoint(
    model: Any,
    folder: Path,
    cfg: TrainConfig,
    state: RunState,
    extra: dict[str, Any],
    live: bool = False,
) -> None:
    """Policy, normalisation, optimizer, RNGs and run state into `folder`, atomically, and
    with `live` (a checkpoint inside a phase, the environments started) the running episodes;
    a disk-full or read-only fault raises `CheckpointError` and keeps the previous one."""
    venv = model.get_vec_normalize_env()
    opt = model.policy.optimizer.state_dict()
    tensors = {
        f"optimizer.state.{i}.{k}": v for i, entry in opt["state"].items() for k, v in entry.items()
    }
    rng_tensors, rng_scalars = _rng_tensors()
    tensors.update(rng_tensors)
    live_scalars = None
    if live:
        live_tensors, live_scalars = _live_tensors(model)
        tensors.update(live_tensors)
    manifest = {
        "n_auvs": cfg.env_spec.n_auvs,
        "n_nodes": cfg.env_spec.n_nodes,
        "env_config": venv.unwrapped.cfg.to_dict(),
        "training_config": cfg.to_dict(),
        "run_state": asdict(state),
        "num_timesteps": int(model.num_timesteps),
        "n_updates": int(model._n_updates),
        "optimizer_param_groups": opt["param_groups"],
        "rng": rng_scalars,
        "live": live_scalars,
        **extra,
    }
    try:
        save_policy(folder, model.policy, normalization_dict(venv), manifest, tensors)
    except PolicyError as exc:
        cause = exc.__cause__
        reason = (cause.strerror or str(cause)) if isinstance(cause, OSError) else str(exc)
        raise CheckpointError(
            f"cannot write checkpoint {folder}: {reason}; the previous checkpoint (if any) is kept"
        ) from exc


def _complete(folder: Path) -> bool:
    """A folder (not a link) holding a checkpoint whose every checksum holds."""
    try:
        if not stat.S_ISDIR(os.lstat(folder).st_mode):
            return False
        read_manifest(folder)
    except (OSError, PolicyError):
        return False
    return True


def recover(folder: Path) -> None:
    """After a kill during `save_checkpoint`: keep a complete `folder`; where it is missing, put
    back the complete `<folder>.tmp` (the newer checkpoint) or `<folder>.old` (the older).
    Partial leftovers are removed; a damaged `folder` is left for loading to report."""
    leftovers = [folder.with_name(folder.name + suffix) for suffix in (".tmp", ".old")]
    if not os.path.lexists(folder):
        for candidate in leftovers:
            if _complete(candidate):
                candidate.rename(folder)
                break
    if _complete(folder):
        for leftover in leftovers:
            remove(leftover)


@dataclass
class Resumed:
    """What a checkpoint restored into a fresh PPO."""

    state: RunState
    live: bool
    """The running episodes were restored too (a checkpoint inside a phase)."""


def restore(model: Any, folder: Path) -> Resumed:
    """Load a checkpoint into `model` (built by the trainer with the same config, on the
    environments of the checkpoint's phase): weights, optimizer, step counts, normalisation
    statistics, every RNG and, for a checkpoint inside a phase, the running episodes.

    Raises:
        CheckpointError: a file is missing, unsafe or damaged, or the checkpoint does not fit
            the model (the message names the folder and the cause).
    """
    try:
        manifest = read_manifest(folder)
        tensors = read_tensors(folder, manifest)
        norm = read_normalization(folder, manifest)
    except PolicyError as exc:
        raise CheckpointError(f"cannot resume from {folder}: {exc}") from exc
    try:
        return _restore(model, manifest, tensors, norm)
    except (
        KeyError,
        TypeError,
        ValueError,
        IndexError,
        RuntimeError,
        SyntaxError,
        RecursionError,
    ) as exc:
        raise CheckpointError(
            f"cannot resume from {folder}: it does not fit this run ({type(exc).__name__}: "
            f"{str(exc)[:200]})"
        ) from exc


def _restore(
    model: Any, manifest: dict[str, Any], tensors: dict[str, torch.Tensor], norm: dict[str, Any]
) -> Resumed:
    state = _run_state(manifest)
    python_rng = ast.literal_eval(manifest["rng"]["python"])  # a tuple literal, no eval
    num_timesteps = _count(manifest["num_timesteps"], "num_timesteps")
    n_updates = _count(manifest["n_updates"], "n_updates")
    model.policy.load_state_dict(
        {k[len("policy.") :]: v for k, v in tensors.items() if k.startswith("policy.")}
    )
    opt_state: dict[int, dict[str, torch.Tensor]] = {}
    for key, value in tensors.items():
        if key.startswith("optimizer.state."):
            _, _, index, name = key.split(".", 3)
            opt_state.setdefault(int(index), {})[name] = value
    model.policy.optimizer.load_state_dict(
        {"state": opt_state, "param_groups": manifest["optimizer_param_groups"]}
    )
    model.num_timesteps, model._n_updates = num_timesteps, n_updates
    venv = model.get_vec_normalize_env()
    venv.obs_rms.mean = np.asarray(norm["obs_mean"])
    venv.obs_rms.var = np.asarray(norm["obs_var"])
    venv.obs_rms.count = norm["obs_count"]
    venv.ret_rms.mean, venv.ret_rms.var = np.float64(norm["ret_mean"]), np.float64(norm["ret_var"])
    venv.ret_rms.count = norm["ret_count"]
    _restore_rngs(tensors, manifest["rng"])
    random.setstate(python_rng)
    live = manifest["live"]
    if live is not None:
        _restore_live(model, tensors, live)
    return Resumed(state, live is not None)


def _restore_live(model: Any, tensors: dict[str, torch.Tensor], scalars: dict[str, Any]) -> None:
    """Put back the running episodes of `_live_tensors` (shapes and dtypes checked)."""
    venv = model.get_vec_normalize_env()
    monitor = _monitor(venv)
    envs = venv.unwrapped
    like = envs.state_arrays()
    saved = {k[len("env.") :]: v for k, v in tensors.items() if k.startswith("env.")}
    envs.load_state_arrays(
        {k: _unbits(v, like[k]) if k in like else v.numpy() for k, v in saved.items()}
    )
    n, obs_shape = envs.num_envs, envs.observation_space.shape
    run = {
        "last_obs": np.zeros((n, *obs_shape), np.float32),
        "episode_starts": np.zeros(n, bool),
        "original_obs": np.zeros((n, *obs_shape), np.float32),
        "returns": np.zeros(n, np.float64),
        "monitor_returns": np.zeros(n, np.float32),
        "monitor_lengths": np.zeros(n, np.int32),
    }
    for name, template in run.items():
        value = _unbits(tensors[f"run.{name}"], template)
        if value.shape != template.shape or value.dtype != template.dtype:
            raise ValueError(
                f"run.{name} is {value.dtype}{list(value.shape)}; accepted "
                f"{template.dtype}{list(template.shape)}"
            )
        run[name] = value.copy()
    model._last_obs, model._last_episode_starts = run["last_obs"], run["episode_starts"]
    venv.old_obs, venv.returns = run["original_obs"], run["returns"]
    model._last_original_obs = venv.get_original_obs()
    monitor.episode_returns = run["monitor_returns"]
    monitor.episode_lengths = run["monitor_lengths"]
    monitor.episode_count = _count(scalars["monitor_episode_count"], "live.monitor_episode_count")


TRAINING_ONLY = ("run_state", "num_timesteps", "n_updates", "optimizer_param_groups", "rng", "live")
"""Manifest entries a checkpoint needs for --resume and a shipped policy does not."""


def export_policy(checkpoint: Path, out: Path) -> dict[str, Any]:
    """A checkpoint as a policy to ship: its network and normalisation, its manifest without
    the optimizer, RNG and run state, with the evaluation it was selected on."""
    try:
        manifest = read_manifest(checkpoint)  # the network's sizes bounded before it is built
        normalization = read_normalization(checkpoint, manifest)
        policy = build_policy(manifest, read_tensors(checkpoint, manifest))
    except PolicyError as exc:
        raise CheckpointError(f"cannot export {checkpoint}: {exc}") from exc
    kept = {
        k: v for k, v in manifest.items() if k not in (*TRAINING_ONLY, "files", "eval", "env_phase")
    }
    kept["eval_at_selection"] = manifest.get("eval")
    save_policy(out, policy, normalization, kept)
    return kept
