"""Policies by name: the baselines, the shipped PPO policies, or a saved policy folder.

Every policy is a callable `policy(env, obs) -> action` (`rollout.EnvPolicy`). A trained
policy is checked against the env it is asked to fly: one trained for another (N, K) is
refused with a message naming both.
"""

from __future__ import annotations

import json
import pickle
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3 import PPO

from iout_mj.agents.baselines import POLICIES, make_policy

SHIPPED_DIR = Path(__file__).resolve().parent / "shipped"


class PolicyError(ValueError):
    """A policy file is missing, unreadable, or made for another scenario."""


def shipped_policies() -> list[str]:
    """Names of the policies shipped with the package."""
    return sorted(p.name for p in SHIPPED_DIR.glob("*") if (p / "model.zip").is_file())


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
    raise PolicyError(
        f"unknown policy {name!r}: accepted {', '.join(POLICIES)}, "
        f"a shipped policy {shipped_policies()}, or a policy file (.zip)"
    )


def load_trained(path: Path, env: Any) -> Any:
    """A `policy(env, obs) -> action` from a saved run folder's model.zip, checked against env."""
    folder = path.parent
    meta_path = folder / "meta.json"
    try:
        model = PPO.load(path, device="cpu")
    except Exception as exc:  # a zip from elsewhere, a truncated file, ...
        raise PolicyError(f"cannot load policy {path}: {type(exc).__name__}: {exc}") from exc
    mission = env.unwrapped.mission
    meta = json.loads(meta_path.read_text()) if meta_path.is_file() else {}
    want = (meta.get("n_auvs"), meta.get("n_nodes"))
    if model.action_space.shape != env.action_space.shape or (
        want != (None, None) and want != (mission.n_auvs, mission.n_nodes)
    ):
        raise PolicyError(
            f"policy {path} was trained for N={want[0]}, K={want[1]} "
            f"(action space {model.action_space}); this env has "
            f"N={mission.n_auvs}, K={mission.n_nodes}"
        )
    stats_path = folder / "vecnormalize.pkl"
    stats = None
    if stats_path.is_file():
        with stats_path.open("rb") as f:
            stats = pickle.load(f)
    return model_policy(model, stats)


def model_policy(model: Any, stats: Any = None) -> Any:
    """A deterministic `policy(env, obs) -> action` from an SB3 model and its VecNormalize
    statistics (None: observations are used as they are)."""

    def act(_env: Any, obs: np.ndarray) -> np.ndarray:
        x = stats.normalize_obs(obs) if stats is not None else obs
        action, _ = model.predict(x, deterministic=True)
        return action

    return act


def load_policy(name: str, env: Any, seed: int = 0) -> Any:
    """A callable `policy(env, obs) -> action`: a baseline name or a trained policy (name or
    file), checked against `env`."""
    if name in POLICIES:
        baseline = make_policy(name, seed)

        def act(e: Any, _obs: np.ndarray) -> np.ndarray:
            return baseline(e.unwrapped.mission)

        act.reset = baseline.reset  # type: ignore[attr-defined]
        return act
    return load_trained(resolve_policy_path(name), env)
