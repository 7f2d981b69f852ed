"""The training configuration: PPO hyperparameters and phases, one YAML per scenario."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from iout_mj.schema import ConfigError, build_dataclass, load_mapping

BACKENDS = ("mujoco", "kinematic")


@dataclass(frozen=True)
class PhaseConfig:
    """One training phase on one backend."""

    backend: str = "mujoco"
    timesteps: int = 100_000

    def __post_init__(self) -> None:
        if self.backend not in BACKENDS:
            raise ConfigError(f"phase backend={self.backend!r}: accepted 'mujoco' or 'kinematic'")
        if self.timesteps < 1:
            raise ConfigError(f"phase timesteps={self.timesteps}: accepted an integer >= 1")


@dataclass(frozen=True)
class TrainConfig:
    """Hyperparameters (rl-zoo style), keyed by scenario; the defaults are those of the
    shipped configs in training/configs."""

    name: str = "ppo"
    n_auvs: int = 2
    n_nodes: int = 7
    layout: str = "paper"
    phases: tuple[PhaseConfig, ...] = (PhaseConfig(),)
    n_envs: int = 8
    n_steps: int = 512
    batch_size: int = 512
    n_epochs: int = 10
    learning_rate: float = 3e-4
    learning_rate_final: float = 3e-5
    """The learning rate falls linearly to this over all phases."""
    ent_coef: float = 0.01
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    net_arch: tuple[int, ...] = (256, 256)
    seed: int = 0
    eval_every_steps: int = 20_000
    eval_episodes: int = 10
    torch_threads: int = 1

    def __post_init__(self) -> None:
        if self.n_envs < 1 or self.n_steps < 1 or self.batch_size < 1:
            raise ConfigError("n_envs, n_steps and batch_size: accepted integers >= 1")
        if (self.n_envs * self.n_steps) % self.batch_size:
            raise ConfigError(
                f"batch_size={self.batch_size} must divide n_envs*n_steps="
                f"{self.n_envs * self.n_steps}"
            )
        if not self.phases:
            raise ConfigError("phases: accepted a non-empty list of {backend, timesteps}")

    @property
    def total_timesteps(self) -> int:
        return sum(p.timesteps for p in self.phases)

    @classmethod
    def load(cls, path: str | Path) -> TrainConfig:
        data = load_mapping(path, "training config")
        config: TrainConfig = build_dataclass(cls, data, Path(path).stem)
        return config

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["phases"] = [dict(p) for p in d["phases"]]
        d["net_arch"] = list(self.net_arch)
        return d
