"""The one episode loop: a policy flies one seeded episode of a gymnasium env."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

import numpy as np


class EnvPolicy(Protocol):
    """`policy(env, obs) -> action`; an optional `reset(seed)` is called at every episode."""

    def __call__(self, env: Any, obs: np.ndarray) -> Any: ...


def run_episode(
    env: Any,
    policy: EnvPolicy,
    seed: int,
    on_step: Callable[[dict[str, Any]], None] | None = None,
) -> dict[str, Any]:
    """Play one episode from `env.reset(seed=seed)`; returns its metrics plus the return (and
    `error` if the physics diverged). `on_step(info)` runs after every step."""
    obs, _ = env.reset(seed=seed)
    reset = getattr(policy, "reset", None)
    if reset is not None:
        reset(seed)
    ret = 0.0
    while True:
        obs, reward, terminated, truncated, info = env.step(policy(env, obs))
        ret += reward
        if on_step is not None:
            on_step(info)
        if terminated or truncated:
            metrics = dict(info["metrics"])
            metrics["return"] = ret
            if "error" in info:
                metrics["error"] = info["error"]
            return metrics
