"""The one colour palette of videos and figures (RGBA in [0, 1]).

Hues already taken, which no AUV may have: the nodes' AoI ramp (green to red), the dock (green,
assets/arena.xml), the node body (blue), AET links (orange), uplinks (cyan) and failed uplinks
(grey). The AUVs therefore take yellow, magenta, white and black; the maps (video and figures)
have a mid-tone seabed on which all four show.
"""

from __future__ import annotations

import numpy as np

AUV_RGBA = np.array(
    [[1.0, 0.95, 0.15, 1], [1.0, 0.3, 0.8, 1], [1.0, 1.0, 1.0, 1], [0.05, 0.05, 0.05, 1]]
)
"""AUV i has colour AUV_RGBA[i % 4] everywhere: yellow, magenta, white, black."""
AET_RGBA = np.array([1.0, 0.55, 0.0, 0.9])
UPLINK_RGBA = np.array([0.1, 0.95, 1.0, 0.9])
FAILED_RGBA = np.array([0.45, 0.45, 0.45, 0.35])
SEABED_RGB = (0.43, 0.40, 0.31)
"""The seabed's mean colour (assets/arena.xml's checker): the background of the trajectory maps."""
NODE_RGB = (0.2, 0.6, 1.0)
"""Nodes where their AoI is not shown (trajectory figures)."""


def auv_rgba(i: int) -> tuple[float, ...]:
    """AUV i's colour as a tuple (matplotlib)."""
    return tuple(float(c) for c in AUV_RGBA[i % len(AUV_RGBA)])


def auv_rgb8(i: int) -> tuple[int, int, int]:
    """AUV i's colour as 8-bit RGB (PIL)."""
    r, g, b = (round(255 * c) for c in AUV_RGBA[i % len(AUV_RGBA)][:3])
    return r, g, b


def aoi_rgba(aoi_frac: np.ndarray) -> np.ndarray:
    """Green (fresh) to red (stale) for AoI / A_max in [0, 1] (clipped: A_max and older are red)."""
    a = np.clip(aoi_frac, 0, 1)[:, None]
    return np.concatenate(
        [0.15 + 0.85 * a, 0.85 - 0.7 * a, 0.2 * np.ones_like(a), np.ones_like(a)], axis=1
    )
