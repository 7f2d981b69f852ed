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


def electrical_energy_j(mechanical_work_j: ArrayLike, motion: MotionConfig) -> FloatArray:
    """The one energy meter: measured actuator work |F v| dt over eta_prop (no hotel load)."""
    return np.asarray(mechanical_work_j, dtype=float) / motion.prop_efficiency


def hotel_energy_j(duration_s: ArrayLike, motion: MotionConfig) -> FloatArray:
    """The hotel load H over a duration."""
    return motion.hotel_power_w * np.asarray(duration_s, dtype=float)
