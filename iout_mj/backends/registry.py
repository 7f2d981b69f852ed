"""The backends: how vehicles move. One registry that every entry point and the tests use."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Backend:
    """A way of moving the vehicles under the same mission rules."""

    name: str
    description: str
    single_env: bool
    """`gymnasium.make` serves it one env at a time (else only batches: the VecEnvs)."""
    extra: str | None = None
    """The optional dependency group it needs (`pip install iout-mj[extra]`), if any."""


BACKENDS: dict[str, Backend] = {
    b.name: b
    for b in (
        Backend("mujoco", "MuJoCo physics: fluid drag, servos, thrusters, measured energy", True),
        Backend("kinematic", "the paper's discrete-time kinematics and cubic energy (fast)", True),
        Backend(
            "warp", "MuJoCo Warp: B scenes per call on a GPU (or Warp's CPU device)", False, "gpu"
        ),
    )
}
SINGLE_ENV_BACKENDS = tuple(name for name, b in BACKENDS.items() if b.single_env)
"""Backends of one env (`gymnasium.make`, the CLI's missions)."""
