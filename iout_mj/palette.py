"""The one colour palette of videos and figures (RGBA in [0, 1])."""

from __future__ import annotations

import numpy as np

AUV_RGBA = np.array(
    [[1.0, 0.85, 0.1, 1], [1.0, 0.3, 0.8, 1], [0.3, 1.0, 0.4, 1], [1.0, 0.5, 0.1, 1]]
)
"""AUV i has colour AUV_RGBA[i % 4] everywhere."""
AET_RGBA = np.array([1.0, 0.55, 0.0, 0.9])
UPLINK_RGBA = np.array([0.1, 0.95, 1.0, 0.9])
FAILED_RGBA = np.array([0.45, 0.45, 0.45, 0.35])


def auv_rgba(i: int) -> tuple[float, ...]:
    """AUV i's colour as a tuple (matplotlib)."""
    return tuple(float(c) for c in AUV_RGBA[i % len(AUV_RGBA)])


def aoi_rgba(aoi_frac: np.ndarray) -> np.ndarray:
    """Green (fresh) to red (stale) for AoI / A_max in [0, 1]."""
    a = np.clip(aoi_frac, 0, 1)[:, None]
    return np.concatenate(
        [0.15 + 0.85 * a, 0.85 - 0.7 * a, 0.2 * np.ones_like(a), np.ones_like(a)], axis=1
    )
