"""Actions: the discrete levels and validation with clear errors.

The action of slot t takes effect in slot t (the paper's eq. 10 moves with the previous
slot's theta and v, a one-slot delay): theta_sp += dtheta, v_sp = clip(v_sp + dv, 0, V_max)
(`iout_begin_env` in `rules.c`). Setpoints accumulate from setpoints, not from measurements, so
both backends see the same heading sequence; headings are never wrapped inside the setpoint.
Docked AUVs stop.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from dm_env import specs

from iout_mj import native
from iout_mj.config import Config
from iout_mj.types import IntArray

ACTION_FIELDS = ("heading", "speed", "aet_node", "uplink_node")


ActionError = native.ActionError
"""An action outside the action space."""


class ActionMap(native.Frozen):
    """The action space of N AUVs and K nodes: 4 integer indices per AUV. The level tables
    are read-only (the compiled rules index them); index ranges are checked in C, by
    `iout_begin_slot`, before anything changes."""

    def __init__(self, cfg: Config, batch: tuple[int, ...] = ()):
        m, n, k = cfg.motion, cfg.scenario.n_auvs, cfg.scenario.n_nodes
        self.cfg, self.batch, self.n_auvs = cfg, batch, n
        self.dtheta_rad = _levels(np.radians(m.dtheta_max_deg), m.heading_levels)
        """Heading change of each heading index."""
        self.dv_mps = _levels(m.dv_max_mps, m.speed_levels)
        """Speed change of each speed index."""
        self.high = native.read_only(
            np.tile(np.array([m.heading_levels, m.speed_levels, k, k], dtype=np.int64), n)
        )
        """Exclusive upper bound of every entry of the flat action."""
        self._freeze()

    def decode(self, action: Any) -> IntArray:
        """Check the shape and integrality of 4 indices per AUV (and a leading env axis when
        batched); returns (*batch, N, 4) indices (their ranges are checked in C)."""
        a = np.asarray(action)
        shape = (*self.batch, self.high.size)
        if a.shape != shape:
            envs = f"{self.batch[0]} rows (one per environment) of " if self.batch else "a flat "
            raise ActionError(
                f"action has shape {a.shape}; accepted {envs}{self.high.size} "
                f"integers: (heading, speed, aet_node, uplink_node) for each of {self.n_auvs} "
                "AUVs"
            )
        integral = a.dtype.kind in "iu" or (
            a.dtype.kind == "f" and bool(np.all(np.isfinite(a))) and bool(np.all(a == np.round(a)))
        )
        if not integral:
            raise ActionError(
                f"action {a.tolist()} has non-integer entries; accepted integer indices"
            )
        if a.dtype.kind in "fu" and np.abs(a.astype(np.float64)).max(initial=0.0) >= 2.0**63:
            raise ActionError(
                f"action {a.tolist()} has entries beyond any index; accepted integer indices "
                f"from 0 to {int(self.high.max()) - 1}"
            )
        return np.asarray(a, dtype=np.int64).reshape(*self.batch, self.n_auvs, 4)

    def spec(self) -> specs.BoundedArray:
        """The dm_env action spec of one environment."""
        return specs.BoundedArray(
            shape=self.high.shape,
            dtype=np.int64,
            minimum=np.zeros_like(self.high),
            maximum=self.high - 1,
            name="action",
        )


def _levels(max_change: float, levels: int) -> np.ndarray:
    """The change of each of `levels` indices, from -max_change to +max_change (read-only)."""
    values = native.allocate((levels,), float)
    values[:] = max_change * (2 * np.arange(levels) / (levels - 1) - 1)
    return native.read_only(values)
