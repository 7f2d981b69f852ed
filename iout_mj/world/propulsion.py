"""Propulsion energy: the paper's cubic model (eqs. 12-13) and the meter of measured work."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from iout_mj.config import MotionConfig
from iout_mj.types import FloatArray


def drag_power_w(speed_mps: ArrayLike, motion: MotionConfig) -> FloatArray:
    """Electrical power for propulsion alone: rho C_d S v^3 / (2 eta_prop)."""
    v = np.asarray(speed_mps, dtype=float)
    return motion.drag_factor_nspm2 * v**3 / motion.prop_efficiency


def propulsion_power_w(speed_mps: ArrayLike, motion: MotionConfig) -> FloatArray:
    """P_prop = rho C_d S v^3 / (2 eta_prop) + H."""
    return drag_power_w(speed_mps, motion) + motion.hotel_power_w


def slot_energy_j(
    speed_mps: ArrayLike, distance_m: ArrayLike, slot_s: float, motion: MotionConfig
) -> FloatArray:
    """E_prop of one slot as the paper writes it (eq. 13): P_prop(v) * d / v.

    With d = v * slot (the paper's kinematics) this is P_prop(v) * slot. For v = 0 the travel
    time d / v is undefined; the vehicle then pays the hotel load over the slot.
    """
    v = np.asarray(speed_mps, dtype=float)
    d = np.asarray(distance_m, dtype=float)
    safe_v = np.where(v > 0, v, 1.0)
    return np.where(
        v > 0, propulsion_power_w(v, motion) * d / safe_v, motion.hotel_power_w * slot_s
    )


class EnergyMeter:
    """The one energy meter of N vehicles: the physics adds measured actuator work |F v| dt
    (surge thrust and yaw, per AUV); `read_j` is the electrical energy since `start`, the work
    over eta_prop (the hotel load is the mission's: `hotel_energy_j`)."""

    def __init__(self, n_auvs: int, motion: MotionConfig):
        self.motion = motion
        self.work_j = np.zeros((n_auvs, 2))
        """Integrated |force x velocity| per AUV: column 0 surge thrust, column 1 yaw."""
        self._start_j = np.zeros((n_auvs, 2))

    def add(self, work_j: FloatArray) -> None:
        """Book measured work (N, 2) (the steppers, once per step)."""
        self.work_j += work_j

    def reset(self) -> None:
        self.work_j[:] = 0.0
        self._start_j[:] = 0.0

    def start(self) -> None:
        """Start a reading (e.g. at the start of a slot)."""
        self._start_j[:] = self.work_j

    def read_j(self) -> FloatArray:
        """(N, 2) electrical energy since `start`: propulsion, yaw (no hotel load)."""
        return (self.work_j - self._start_j) / self.motion.prop_efficiency


def hotel_energy_j(duration_s: ArrayLike, motion: MotionConfig) -> FloatArray:
    """The hotel load H over a duration."""
    return motion.hotel_power_w * np.asarray(duration_s, dtype=float)
