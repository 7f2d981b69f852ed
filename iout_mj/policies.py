"""Trained (PPO) policies: load a shipped name or a file, check it fits the env."""

from __future__ import annotations

from pathlib import Path
from typing import Any

SHIPPED_DIR = Path(__file__).resolve().parent / "policies"


class PolicyError(ValueError):
    """A policy file is missing, unreadable, or made for another scenario."""


def resolve_policy_path(name: str) -> Path:
    """A shipped policy name (e.g. 'ppo-n2-k7') or a path to a saved policy (.zip)."""
    shipped = SHIPPED_DIR / name / "model.zip"
    if shipped.is_file():
        return shipped
    path = Path(name)
    if path.is_dir() and (path / "model.zip").is_file():
        return path / "model.zip"
    if path.is_file():
        return path
    available = sorted(p.name for p in SHIPPED_DIR.glob("*") if (p / "model.zip").is_file())
    raise PolicyError(
        f"unknown policy {name!r}: accepted greedy, round-robin, random-walk, "
        f"planner, a shipped policy {available}, or a policy file (.zip)"
    )


def load_trained_policy(name: str, env: Any) -> Any:
    """A callable `policy(env, obs) -> action` for a trained PPO policy."""
    path = resolve_policy_path(name)
    from iout_mj.training import load_for_env

    return load_for_env(path, env)
