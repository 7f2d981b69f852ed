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
    max_steps: int | None = None,
) -> dict[str, Any]:
    """Play one episode from `env.reset(seed=seed)`; returns its metrics plus the return (and
    `error` if the physics diverged). `on_step(info)` runs after every step. With `max_steps`
    the episode may stop early: its metrics are then those of the slots flown (`stopped_at`
    gives the slot; the AoI over the horizon is undefined and left out)."""
    obs, _ = env.reset(seed=seed)
    reset = getattr(policy, "reset", None)
    if reset is not None:
        reset(seed)
    ret = 0.0
    steps = 0
    while True:
        obs, reward, terminated, truncated, info = env.step(policy(env, obs))
        ret += reward
        steps += 1
        if on_step is not None:
            on_step(info)
        if not (terminated or truncated) and max_steps is not None and steps >= max_steps:
            metrics = env.unwrapped.mission.metrics()
            del metrics["mean_aoi_horizon"]
            return {**metrics, "return": ret, "stopped_at": steps}
        if terminated or truncated:
            metrics = dict(info["metrics"])
            metrics["return"] = ret
            if "error" in info:
                metrics["error"] = info["error"]
            return metrics
