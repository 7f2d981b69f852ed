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


class ActionError(ValueError):
    """An action outside the action space."""


class ActionMap:
    """The action space of N AUVs and K nodes: 4 integer indices per AUV."""

    def __init__(self, cfg: Config, batch: tuple[int, ...] = ()):
        m, n, k = cfg.motion, cfg.scenario.n_auvs, cfg.scenario.n_nodes
        self.cfg, self.batch, self.n_auvs = cfg, batch, n
        self.dtheta_rad = np.radians(m.dtheta_max_deg) * (
            2 * np.arange(m.heading_levels) / (m.heading_levels - 1) - 1
        )
        """Heading change of each heading index."""
        self.dv_mps = m.dv_max_mps * (2 * np.arange(m.speed_levels) / (m.speed_levels - 1) - 1)
        """Speed change of each speed index."""
        self.high = np.tile(np.array([m.heading_levels, m.speed_levels, k, k], dtype=np.int64), n)
        """Exclusive upper bound of every entry of the flat action."""

    def decode(self, action: Any) -> IntArray:
        """Validate 4 integers per AUV (and a leading env axis when batched); returns
        (*batch, N, 4) indices."""
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
        a = np.ascontiguousarray(a, dtype=np.int64)
        bad = native.lib.iout_first_bad_action(
            native.address(a), a.size, native.address(self.high), self.high.size
        )
        if bad >= 0:
            env, j = divmod(bad, self.high.size)
            auv, f = divmod(j, 4)
            where = f"env {env}, " if self.batch else ""
            raise ActionError(
                f"{where}AUV {auv}: {ACTION_FIELDS[f]} index {int(a.flat[bad])} "
                f"is out of range; accepted 0 to {int(self.high[j]) - 1}"
            )
        return a.reshape(*self.batch, self.n_auvs, 4)

    def spec(self) -> specs.BoundedArray:
        """The dm_env action spec of one environment."""
        return specs.BoundedArray(
            shape=self.high.shape,
            dtype=np.int64,
            minimum=np.zeros_like(self.high),
            maximum=self.high - 1,
            name="action",
        )
