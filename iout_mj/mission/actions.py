"""Actions: the discrete levels, validation with clear errors, and the setpoint dynamics.

The action of slot t takes effect in slot t (the paper's eq. 10 moves with the previous
slot's theta and v, a one-slot delay): theta_sp += dtheta, v_sp = clip(v_sp + dv, 0, V_max).
Setpoints accumulate from setpoints, not from measurements, so both backends see the same
heading sequence; headings are never wrapped inside the setpoint. Docked AUVs stop.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from dm_env import specs

from iout_mj.config import Config
from iout_mj.mission.state import MissionState
from iout_mj.types import FloatArray, IntArray
from iout_mj.world.geometry import unit_xy

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
        self.high = np.tile([m.heading_levels, m.speed_levels, k, k], n)
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
            a.dtype.kind == "f" and np.all(np.isfinite(a)) and np.all(a == np.round(a))
        )
        if not integral:
            raise ActionError(
                f"action {a.tolist()} has non-integer entries; accepted integer indices"
            )
        a = a.astype(np.int64, copy=False)
        bad = (a < 0) | (a >= self.high)
        if bad.any():
            env, j = divmod(int(np.argmax(bad)), self.high.size)
            auv, f = divmod(j, 4)
            where = f"env {env}, " if self.batch else ""
            raise ActionError(
                f"{where}AUV {auv}: {ACTION_FIELDS[f]} index {int(a.flat[env * a.shape[-1] + j])} "
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

    def apply(self, s: MissionState, a: IntArray, area_m: FloatArray) -> None:
        """New heading and speed setpoints from decoded actions `a`, the straight-line end of
        the slot's move, and whether that end leaves the area (a boundary attempt)."""
        moving = ~s.docked
        s.action[...] = a
        s.heading_sp += np.where(moving, self.dtheta_rad[a[..., 0]], 0.0)
        s.speed_sp[...] = np.where(
            moving,
            np.minimum(
                np.maximum(s.speed_sp + self.dv_mps[a[..., 1]], 0.0), self.cfg.motion.v_max_mps
            ),
            0.0,
        )
        step_m = (s.speed_sp * self.cfg.scenario.slot_s)[..., None] * unit_xy(s.heading_sp)
        s.straight_end_m[...] = s.positions_m + step_m
        end = s.straight_end_m
        s.boundary_attempt[...] = moving & ((end < 0) | (end > area_m)).any(axis=-1)
