"""The paper's rules of a slot, compiled (`rules.c`): one implementation for every backend.

A backend moves the vehicles; everything the paper defines on top of the motion happens in
C: setpoints from actions (`iout_begin_slot`), then energy, the sensor network
(`world/network.c`), docking, termination, the reward terms (`rewards.c`), statistics, the log
and the observation (`iout_end_slot`, `iout_observe`). Every C function loops over the
environments of a batch, one env being a batch of one (`MissionState.arrays`), so the single
env, the SB3 and gymnasium batches, the MuJoCo task and the Warp backend run the same lines.
Why C: in numpy the rules were ~200 calls per slot on arrays of a few elements (most of a
kinematic step's 260 us); in C they are one call through ctypes with one pointer
(`MissionView`), and the library adds no memory or start-up cost (numba, tried first, added
~130 MB resident to every process).

This module holds what Python gives the C code: the constants of a config (one record of
`PARAMS_DTYPE`), and the struct of pointers to a mission's arrays.
"""

from __future__ import annotations

import ctypes
import dataclasses

import numpy as np

from iout_mj import native
from iout_mj.config import Config, RewardWeights
from iout_mj.mission.observation import ENERGY_OBS_REF_J, OBS_HIGH
from iout_mj.mission.rewards import REWARD_TERMS
from iout_mj.mission.state import LogArrays, MissionArrays
from iout_mj.types import FloatArray
from iout_mj.world import propulsion
from iout_mj.world.acoustics import LINK_DTYPE
from iout_mj.world.network import NETWORK_STRUCT, NetworkArrays

COLLISION_DISTANCE_M = 5.0
"""Two hulls (3 m long) closer than this in a slot count as one collision (per pair and slot)."""

_SCALARS = (
    ("slot_s", np.float64),
    ("horizon_slots", np.int64),
    ("area_x_m", np.float64),
    ("area_y_m", np.float64),
    ("inv_diag_per_m", np.float64),
    ("dock_x_m", np.float64),
    ("dock_y_m", np.float64),
    ("dock_radius_m", np.float64),
    ("v_max_mps", np.float64),
    ("hotel_j", np.float64),
    ("drag_power_w_at_1mps", np.float64),
    ("k_reset", np.int64),
    ("aoi_max", np.float64),
    ("deadline_speed_mps", np.float64),
    ("fairness_lambda", np.float64),
    ("fairness_min_deliveries", np.int64),
    ("stall_distance_m", np.float64),
    ("margin_epsilon_j", np.float64),
    ("collision_sigma_m", np.float64),
    ("safety_distance_m", np.float64),
    ("collision_distance_m", np.float64),
    ("energy_obs_ref_j", np.float64),
    ("obs_high", np.float64),
)
PARAMS_DTYPE = np.dtype(
    [*_SCALARS, *((f"w_{f.name}", np.float64) for f in dataclasses.fields(RewardWeights))]
)
"""Every constant the rules read: the scalars above and the signed reward weights."""


def params(cfg: Config) -> np.ndarray:
    """The (1,) PARAMS_DTYPE record of a config."""
    sc, m, r, net = cfg.scenario, cfg.motion, cfg.reward, cfg.network
    values = {
        "slot_s": sc.slot_s,
        "horizon_slots": sc.horizon_slots,
        "area_x_m": sc.area_m[0],
        "area_y_m": sc.area_m[1],
        "inv_diag_per_m": 1.0 / float(np.hypot(*sc.area_m)),
        "dock_x_m": sc.dock_center_m[0],
        "dock_y_m": sc.dock_center_m[1],
        "dock_radius_m": sc.dock_radius_m,
        "v_max_mps": m.v_max_mps,
        "hotel_j": float(propulsion.hotel_energy_j(sc.slot_s, m)),
        "drag_power_w_at_1mps": float(propulsion.drag_power_w(1.0, m)),
        "k_reset": net.k_reset,
        "aoi_max": net.aoi_max,
        "deadline_speed_mps": r.deadline_speed_mps,
        "fairness_lambda": r.fairness_lambda,
        "fairness_min_deliveries": r.fairness_min_deliveries,
        "stall_distance_m": r.stall_distance_m,
        "margin_epsilon_j": r.margin_epsilon_j,
        "collision_sigma_m": r.collision_sigma_m,
        "safety_distance_m": r.safety_distance_m,
        "collision_distance_m": COLLISION_DISTANCE_M,
        "energy_obs_ref_j": ENERGY_OBS_REF_J,
        "obs_high": OBS_HIGH,
        **{f"w_{k}": v for k, v in dataclasses.asdict(r.weights).items()},
    }
    record = np.zeros(1, dtype=PARAMS_DTYPE)
    for name in PARAMS_DTYPE.names or ():
        record[name] = values[name]
    return record


def unserved_aoi_sum(params: np.ndarray, slot: int, aoi: FloatArray) -> float:
    """Sum over the slots left until T_max of the mean AoI if no node is served again (the
    compiled `iout_unserved_aoi_sum`, booked when an episode ends early)."""
    a = np.ascontiguousarray(aoi, dtype=float)
    return float(
        native.lib.iout_unserved_aoi_sum(native.address(params), slot, native.address(a), a.size)
    )


STATE_STRUCT = native.pointers("State", MissionArrays._fields)
LOG_STRUCT = native.pointers("Log", LogArrays._fields)
INPUTS = (
    "actions",
    "end_positions_m",
    "end_headings_rad",
    "end_speeds_mps",
    "propulsion_energy_j",
    "yaw_energy_j",
    "path_m",
    "terms",
    "obs",
)
"""The slot's inputs and outputs, after the state in `Mission` (native.h)."""


class MissionView(ctypes.Structure):
    """`Mission` of native.h: what the compiled rules read and write for one `Mission`."""

    _fields_ = [
        ("n_envs", ctypes.c_int64),
        ("n_auvs", ctypes.c_int64),
        ("n_nodes", ctypes.c_int64),
        ("n_path", ctypes.c_int64),
        ("p", ctypes.c_void_p),
        ("link", ctypes.c_void_p),
        ("dtheta_rad", ctypes.c_void_p),
        ("dv_mps", ctypes.c_void_p),
        ("s", STATE_STRUCT),
        ("net", NETWORK_STRUCT),
        ("log", LOG_STRUCT),
        *((name, ctypes.c_void_p) for name in INPUTS),
    ]


native.require_layout(
    ";".join(
        [
            "params:" + ",".join(PARAMS_DTYPE.names or ()),
            "link:" + ",".join(LINK_DTYPE.names or ()),
            "network:" + ",".join(NetworkArrays._fields),
            "state:" + ",".join(MissionArrays._fields),
            "log:" + ",".join(LogArrays._fields),
            "terms:" + ",".join(REWARD_TERMS),
            "mission:" + ",".join(f[0] for f in MissionView._fields_),
        ]
    )
)
