"""Planar geometry on arrays with any leading axes (numpy): norms, headings, distances."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from iout_mj.types import FloatArray


def norm_xy(v: FloatArray) -> FloatArray:
    """Length of (x, y) vectors stored along the last axis."""
    return np.hypot(v[..., 0], v[..., 1])


_QUARTER_TURN = np.array([0.0, np.pi / 2])


def unit_xy(angle_rad: FloatArray) -> FloatArray:
    """(cos, sin) of angles, along a new last axis (sin a = cos(a - pi/2): one call)."""
    return np.cos(np.asarray(angle_rad)[..., None] - _QUARTER_TURN)


def wrap_angle(angle_rad: Any) -> Any:
    """Wrap angles to (-pi, pi], the one convention of headings (C: `iout_wrap_angle`)."""
    return np.pi - np.mod(np.pi - np.asarray(angle_rad), 2 * np.pi)


def pairwise_distance_m(auv_xy: ArrayLike, nodes_xy: ArrayLike) -> FloatArray:
    """Distances (*batch, N, K) between N AUV positions and K node positions."""
    diff = np.asarray(auv_xy, dtype=float)[..., :, None, :] - np.asarray(nodes_xy)[..., None, :, :]
    return norm_xy(diff)


def slot_velocity_mps(
    heading_rad: ArrayLike, speed_mps: ArrayLike, current_mps: ArrayLike, v_max_mps: float
) -> FloatArray:
    """(..., 2) velocity over the ground of an AUV flying a slot at its heading and speed
    setpoints in a current (the kinematic backend's move, C: `iout_kinematic_slot`): the speed
    setpoint over the ground along the heading (the hull's servo holds it), at most V_max
    through the water, plus the current's component across the heading."""
    angle = np.asarray(heading_rad, dtype=float)
    heading = np.stack([np.cos(angle), np.sin(angle)], axis=-1)  # as C computes it
    current = np.asarray(current_mps, dtype=float)
    along = np.sum(heading * current, axis=-1, keepdims=True)
    ground = np.minimum(np.asarray(speed_mps, dtype=float)[..., None], v_max_mps + along)
    return ground * heading + (current - along * heading)
