"""Shared fixtures: configs, RNGs, scenarios and the command line."""

import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

# One torch thread per process: pytest-xdist runs a worker per core, and a second torch thread
# per worker (torch's default is one per core) oversubscribes the cores and slows PPO many times
# over. Set before torch is imported; the commands the tests start inherit it.
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np
import pytest

import iout_mj  # noqa: F401  (chooses the GL backend and registers the env first)
from iout_mj.config import Config
from iout_mj.scenarios import make_config

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def cfg() -> Config:
    return make_config(2, 7)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(0)


def run_cli(
    *args: object, check: bool = True, cwd: Path | None = None
) -> subprocess.CompletedProcess:
    """`iout-mj ARGS` in a fresh interpreter, as a user runs it."""
    return subprocess.run(
        [sys.executable, "-m", "iout_mj.cli", *map(str, args)],
        capture_output=True,
        text=True,
        check=check,
        cwd=cwd,
    )


def tiny_training(**changes: object) -> object:
    """A training config of a few hundred kinematic steps (pipeline tests), with `changes`."""
    from iout_mj.training import PhaseConfig, TrainConfig

    base: dict = {
        "name": "t",
        "n_auvs": 1,
        "n_nodes": 7,
        "n_envs": 2,
        "n_steps": 64,
        "batch_size": 64,
        "n_epochs": 1,
        "net_arch": (32, 32),
        "eval_every_steps": 128,
        "eval_episodes": 1,
        "phases": (PhaseConfig("kinematic", 128), PhaseConfig("kinematic", 128)),
    }
    return TrainConfig(**{**base, **changes})


@pytest.fixture
def cli() -> Callable[..., subprocess.CompletedProcess]:
    return run_cli


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Longest first: the README-commands test (minutes), then the other slow tests, then the
    rest, each group in file order, so that the test workers (pytest-xdist, one per core) end
    together instead of one waiting for a long test started last."""

    def rank(item: pytest.Item) -> int:
        if item.path.name == "test_readme_commands.py":
            return 0
        return 1 if item.get_closest_marker("slow") else 2

    items.sort(key=rank)
