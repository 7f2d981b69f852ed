"""Run folders: checkpoints in the safe policy format, replaced whole or not at all.

A run folder holds `config.yaml` (the exact training config), `last/` and `best/` (policy
folders, `agents.policy_format`, whose manifests also hold the run state, so a checkpoint is
self-describing), `state.json` (a copy of the last run state, for people and figures) and
TensorBoard logs under `tb/`. A training checkpoint adds the optimizer state and every RNG
(torch, numpy's global one that SB3's minibatches draw from, the environments' batch RNG) to
the weights file, so `--resume` continues the schedule, the statistics and the random streams.
"""

from __future__ import annotations

import ast
import json
import random
import shutil
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from iout_mj.agents.policy_format import (
    MANIFEST,
    NORMALIZATION,
    PolicyFormatError,
    normalization_dict,
    read_manifest,
    read_tensors,
    save_policy,
    write_atomic,
)
from iout_mj.errors import CheckpointError
from iout_mj.training.config import TrainConfig


@dataclass
class RunState:
    """Where a run stands: in every checkpoint's manifest, and copied to `state.json`."""

    phase: int = 0
    num_timesteps: int = 0
    best_score: float = -1e300
    history: list[dict[str, Any]] = field(default_factory=list)

    def save(self, path: Path) -> None:
        write_atomic(path, (json.dumps(asdict(self), indent=1) + "\n").encode())


def _rng_tensors(batch_rng: np.random.RandomState) -> tuple[dict[str, torch.Tensor], Any]:
    """Every RNG state: tensors for the weights file, the rest as JSON."""
    global_state: Any = np.random.get_state()
    env_state: Any = batch_rng.get_state()
    np_key, np_pos, np_gauss, np_cached = global_state[1:]
    env_key, env_pos, env_gauss, env_cached = env_state[1:]
    tensors = {
        "rng.torch": torch.get_rng_state(),
        "rng.numpy_key": torch.from_numpy(np.asarray(np_key, dtype=np.int64)),
        "rng.env_key": torch.from_numpy(np.asarray(env_key, dtype=np.int64)),
    }
    scalars = {
        "numpy": [int(np_pos), int(np_gauss), float(np_cached)],
        "env": [int(env_pos), int(env_gauss), float(env_cached)],
        "python": repr(random.getstate()),
    }
    return tensors, scalars


def _restore_rngs(
    tensors: dict[str, torch.Tensor], scalars: dict[str, Any]
) -> np.random.RandomState:
    torch.set_rng_state(tensors["rng.torch"])
    pos, gauss, cached = scalars["numpy"]
    key = tensors["rng.numpy_key"].numpy().astype(np.uint32)
    np.random.set_state(("MT19937", key, pos, gauss, cached))
    env = np.random.RandomState()
    pos, gauss, cached = scalars["env"]
    env.set_state(("MT19937", tensors["rng.env_key"].numpy().astype(np.uint32), pos, gauss, cached))
    return env


def save_checkpoint(
    model: Any, folder: Path, cfg: TrainConfig, state: RunState, extra: dict[str, Any]
) -> None:
    """Policy, normalisation, optimizer, RNGs and run state into `folder`, atomically; a
    disk-full or read-only fault raises `CheckpointError` and keeps the previous one."""
    venv = model.get_vec_normalize_env()
    batch = venv.unwrapped
    opt = model.policy.optimizer.state_dict()
    tensors = {
        f"optimizer.state.{i}.{k}": v for i, entry in opt["state"].items() for k, v in entry.items()
    }
    rng_tensors, rng_scalars = _rng_tensors(batch.random)
    tensors.update(rng_tensors)
    manifest = {
        "n_auvs": cfg.n_auvs,
        "n_nodes": cfg.n_nodes,
        "env_config": batch.cfg.to_dict(),
        "training_config": cfg.to_dict(),
        "run_state": asdict(state),
        "num_timesteps": int(model.num_timesteps),
        "n_updates": int(model._n_updates),
        "optimizer_param_groups": opt["param_groups"],
        "rng": rng_scalars,
        **extra,
    }
    try:
        save_policy(folder, model.policy, normalization_dict(venv), manifest, tensors)
    except OSError as exc:
        shutil.rmtree(folder.with_name(folder.name + ".tmp"), ignore_errors=True)
        raise CheckpointError(
            f"cannot write checkpoint {folder}: {exc.strerror or exc}; the previous "
            f"checkpoint (if any) is kept"
        ) from exc


def recover(folder: Path) -> None:
    """After a kill during `save_checkpoint`: put back a complete `<folder>.tmp` (the newer
    checkpoint) or `<folder>.old` (the older) where `folder` is missing."""
    if (folder / MANIFEST).is_file():
        return
    for candidate in (
        folder.with_name(folder.name + ".tmp"),
        folder.with_name(folder.name + ".old"),
    ):
        try:
            read_manifest(candidate)
        except PolicyFormatError:
            continue
        shutil.rmtree(folder, ignore_errors=True)
        candidate.rename(folder)
        return


@dataclass
class Resumed:
    """What a checkpoint restores into a fresh PPO."""

    state: RunState
    env_rng: np.random.RandomState


def restore(model: Any, folder: Path) -> Resumed:
    """Load a checkpoint into `model` (built by the trainer with the same config): weights,
    optimizer, step counts, normalisation statistics and every RNG."""
    try:
        manifest = read_manifest(folder)
        tensors = read_tensors(folder)
        norm = json.loads((folder / "normalization.json").read_text())
    except (PolicyFormatError, OSError, json.JSONDecodeError) as exc:
        raise CheckpointError(f"cannot resume from {folder}: {exc}") from exc
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
    model.num_timesteps = manifest["num_timesteps"]
    model._n_updates = manifest["n_updates"]
    venv = model.get_vec_normalize_env()
    venv.obs_rms.mean = np.asarray(norm["obs_mean"])
    venv.obs_rms.var = np.asarray(norm["obs_var"])
    venv.obs_rms.count = norm["obs_count"]
    venv.ret_rms.mean, venv.ret_rms.var = np.float64(norm["ret_mean"]), np.float64(norm["ret_var"])
    venv.ret_rms.count = norm["ret_count"]
    env_rng = _restore_rngs(tensors, manifest["rng"])
    random.setstate(ast.literal_eval(manifest["rng"]["python"]))  # a tuple literal, no eval
    return Resumed(RunState(**manifest["run_state"]), env_rng)


TRAINING_ONLY = ("run_state", "num_timesteps", "n_updates", "optimizer_param_groups", "rng")
"""Manifest entries a checkpoint needs for --resume and a shipped policy does not."""


def export_policy(checkpoint: Path, out: Path) -> dict[str, Any]:
    """A checkpoint as a policy to ship: its network and normalisation, its manifest without
    the optimizer, RNG and run state, with the evaluation it was selected on."""
    try:
        manifest = read_manifest(checkpoint)
        tensors = read_tensors(checkpoint)
        normalization = json.loads((checkpoint / NORMALIZATION).read_text())
    except (PolicyFormatError, OSError, json.JSONDecodeError) as exc:
        raise CheckpointError(f"cannot export {checkpoint}: {exc}") from exc
    from iout_mj.agents.policy_format import build_policy

    policy = build_policy(manifest, tensors)
    kept = {
        k: v for k, v in manifest.items() if k not in (*TRAINING_ONLY, "files", "eval", "env_phase")
    }
    kept["eval_at_selection"] = manifest.get("eval")
    save_policy(out, policy, normalization, kept)
    return kept
