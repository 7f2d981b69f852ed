"""Run folders: the run state, and checkpoints replaced whole or not at all.

A run folder holds `config.yaml` (the exact config), `last/` and `best/` (each: `model.zip`,
`vecnormalize.pkl`, `meta.json`), `state.json` (phase, step count, evaluation history) and
TensorBoard logs under `tb/`.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from iout_mj.training.config import TrainConfig


@dataclass
class RunState:
    """Where a run stands: written to `state.json` at every checkpoint."""

    phase: int = 0
    num_timesteps: int = 0
    best_score: float = -np.inf
    history: list[dict[str, Any]] = field(default_factory=list)

    @classmethod
    def load(cls, path: Path) -> RunState:
        return cls(**json.loads(path.read_text()))

    def save(self, path: Path) -> None:
        path.write_text(json.dumps(asdict(self), indent=1) + "\n")


def save_checkpoint(
    model: Any, venv: Any, folder: Path, cfg: TrainConfig, extra: dict[str, Any]
) -> None:
    """Model, normalisation statistics and metadata into `folder`, replaced atomically."""
    tmp = folder.with_name(folder.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    model.save(tmp / "model.zip")
    venv.save(str(tmp / "vecnormalize.pkl"))
    meta = {"n_auvs": cfg.n_auvs, "n_nodes": cfg.n_nodes, "config": cfg.to_dict(), **extra}
    (tmp / "meta.json").write_text(json.dumps(meta, indent=2) + "\n")
    shutil.rmtree(folder, ignore_errors=True)
    tmp.rename(folder)  # a checkpoint is replaced whole or not at all
