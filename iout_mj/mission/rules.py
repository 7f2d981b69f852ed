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
from iout_mj.types import FloatArray
from iout_mj.world import propulsion

COLLISION_DISTANCE_M = 5.0
"""Two hulls (3 m long) closer than this in a slot count as one collision (per pair and slot)."""

PARAMS_DTYPE = native.record_dtype("Params")
"""Every constant the rules read (native.h's IOUT_PARAMS): scalars and the signed reward
weights, at the compiled library's offsets."""


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
        "dock_max_speed_mps": np.inf if sc.dock_max_speed_mps is None else sc.dock_max_speed_mps,
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
    native.require_names("Params", tuple(sorted(PARAMS_DTYPE.names or ())), tuple(sorted(values)))
    record = native.allocate((1,), PARAMS_DTYPE)
    for name, value in values.items():
        record[name] = value
    return native.read_only(record)


def unserved_aoi_sum(params: np.ndarray, slot: int, aoi: FloatArray) -> float:
    """Sum over the slots left until T_max of the mean AoI if no node is served again (the
    compiled `iout_unserved_aoi_sum`, booked when an episode ends early)."""
    a = np.ascontiguousarray(aoi, dtype=float)
    out = ctypes.c_double()
    native.call(
        native.lib.iout_unserved_aoi_sum,
        native.address(params),
        slot,
        native.address(a),
        a.size,
        ctypes.byref(out),
    )
    return out.value


INPUTS = {
    "actions": np.dtype(np.int64),
    "end_positions_m": np.dtype(float),
    "end_headings_rad": np.dtype(float),
    "end_speeds_mps": np.dtype(float),
    "propulsion_energy_j": np.dtype(float),
    "yaw_energy_j": np.dtype(float),
    "path_m": np.dtype(float),
    "terms": np.dtype(float),
    "obs": np.dtype(float),
    "channel_draws": np.dtype(float),
    "link_sinr_db": np.dtype(float),
    "link_per": np.dtype(float),
    "link_packets_sent": np.dtype(np.int64),
    "link_packets_received": np.dtype(np.int64),
}
"""The slot's inputs and outputs that `Mission` shares with the rules (IOUT_MISSION_IO): the
channel's uniform draws of the slot and its per-AUV link outcomes among them."""
SIZES = (
    "n_envs",
    "n_auvs",
    "n_nodes",
    "horizon_slots",
    "heading_levels",
    "speed_levels",
    "n_obs",
    "n_path",
)
"""The sizes in a mission's view, which bound every index the rules use (checked in C)."""
CONSTANTS = ("p", "link", "channel", "dtheta_rad", "dv_mps", "auv_depth_m", "node_depth_m")
"""The read-only constants a mission's view points to."""

native.require_fields(
    "Mission",
    {
        **{name: np.dtype(np.int64) for name in SIZES},
        **{name: None for name in (*CONSTANTS, "s", "net", "log")},
        **INPUTS,
    },
)
native.require_names(
    "the reward weights",
    tuple(f for f in PARAMS_DTYPE.names or () if f.startswith("w_")),
    tuple(f"w_{f.name}" for f in dataclasses.fields(RewardWeights)),
)
MissionView = native.struct_type("Mission")
"""`Mission` of native.h: what the compiled rules read and write for one `Mission`."""
