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
