"""Episode statistics: the per-slot log, the metrics, the trace, and the one episode summary."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from iout_mj.config import Config
from iout_mj.mission.state import MissionState
from iout_mj.types import BoolArray, FloatArray, IntArray
from iout_mj.world.geometry import norm_xy, pair_indices
from iout_mj.world.network import SensorNetwork, jain_index

COLLISION_DISTANCE_M = 5.0
"""Two hulls (3 m long) closer than this in a slot count as one collision (per pair and slot)."""


@dataclass
class MissionLog:
    """Per-slot history of one episode (for metrics, figures and rendering; one env only)."""

    positions_m: list[FloatArray] = field(default_factory=list)
    headings_rad: list[FloatArray] = field(default_factory=list)
    speeds_mps: list[FloatArray] = field(default_factory=list)
    mean_aoi: list[float] = field(default_factory=list)
    jain: list[float] = field(default_factory=list)
    aet_nodes: list[IntArray] = field(default_factory=list)
    uplink_nodes: list[IntArray] = field(default_factory=list)
    uplink_ok: list[BoolArray] = field(default_factory=list)

    def record(self, s: MissionState, net: SensorNetwork, uplink_ok: BoolArray | None) -> None:
        """Append the state at the end of a slot (at the start, after a reset)."""
        self.positions_m.append(s.positions_m.copy())
        self.headings_rad.append(s.headings_rad.copy())
        self.speeds_mps.append(s.speeds_mps.copy())
        self.mean_aoi.append(float(net.mean_aoi))
        self.jain.append(float(net.jain))
        if uplink_ok is not None:
            self.aet_nodes.append(s.action[:, 2].copy())
            self.uplink_nodes.append(s.action[:, 3].copy())
            self.uplink_ok.append(uplink_ok.copy())


def unserved_aoi_sum(cfg: Config, slot: IntArray, aoi: FloatArray) -> FloatArray:
    """Sum over the slots left until T_max of the mean AoI if no node is served again:
    sum_{j=1..L} min(a + j, A_max) per node, in closed form."""
    a_max = cfg.network.aoi_max
    left = np.maximum(cfg.scenario.horizon_slots - slot, 0)[..., None]
    rising = np.clip(np.floor(a_max - aoi), 0, left)  # slots before the cap is reached
    total = rising * aoi + rising * (rising + 1) / 2 + (left - rising) * a_max
    return total.mean(axis=-1)


def book_separation(s: MissionState, path_m: FloatArray, was_docked: BoolArray) -> None:
    """Closest approach and collisions over a slot's path (S, *batch, N, 2); pairs of AUVs
    both parked at the dock are left out."""
    n = path_m.shape[-2]
    if n < 2:
        return
    iu, ju = pair_indices(n)
    gap = norm_xy(path_m[..., iu, :] - path_m[..., ju, :]).min(axis=0)
    gap = np.where(was_docked[..., iu] & was_docked[..., ju], np.inf, gap)
    np.minimum(s.min_separation_m, gap.min(axis=-1), out=s.min_separation_m)
    s.collisions += (gap < COLLISION_DISTANCE_M).sum(axis=-1)


def metrics(cfg: Config, s: MissionState, net: SensorNetwork, i: Any = ()) -> dict[str, Any]:
    """Episode metrics of environment `i` (() for one env; time averages over the slots played
    so far)."""
    slot = int(s.slot[i])
    slots = max(slot, 1)
    min_sep = float(s.min_separation_m[i])
    return {
        "mean_aoi": float(s.sum_mean_aoi[i]) / slots,
        "mean_aoi_horizon": float(s.sum_mean_aoi[i] + s.aoi_after_mission[i])
        / max(slot, cfg.scenario.horizon_slots),
        "objective": float(s.sum_objective[i]) / slots,
        "jain": float(jain_index(net.deliveries[i])),
        "delivered_bits": float(net.delivered_bits[i]),
        "propulsion_energy_j": s.propulsion_energy_j[i].tolist(),
        "yaw_energy_j": s.yaw_energy_j[i].tolist(),
        "min_separation_m": min_sep if np.isfinite(min_sep) else None,
        "docked": s.docked[i].tolist(),
        "mission_slots": slot,
        "collisions": int(s.collisions[i]),
        "deliveries_per_node": net.deliveries[i].tolist(),
    }


SUMMARY_KEYS = (
    "mean_aoi",
    "mean_aoi_horizon",
    "objective",
    "jain",
    "delivered_bits",
    "propulsion_energy_j",
    "docking_rate",
    "collisions",
)
"""The scalar summary of an episode, in report order (evaluation rows, training history)."""


def episode_summary(m: dict[str, Any]) -> dict[str, float]:
    """An episode's metrics as scalars: propulsion energy is the mean per AUV, docking_rate
    1.0 if every AUV docked."""
    return {
        "mean_aoi": m["mean_aoi"],
        "mean_aoi_horizon": m["mean_aoi_horizon"],
        "objective": m["objective"],
        "jain": m["jain"],
        "delivered_bits": m["delivered_bits"],
        "propulsion_energy_j": float(np.mean(m["propulsion_energy_j"])),
        "docking_rate": float(all(m["docked"])),
        "collisions": float(m["collisions"]),
    }


def trace(cfg: Config, log: MissionLog, net: SensorNetwork) -> dict[str, Any]:
    """The episode's path and service, as plain lists (for figures and JSON; one env)."""
    sc = cfg.scenario
    return {
        "positions_m": np.array(log.positions_m).tolist(),
        "headings_rad": np.array(log.headings_rad).tolist(),
        "speeds_mps": np.array(log.speeds_mps).tolist(),
        "nodes_m": net.nodes_m.tolist(),
        "delivered_bits_per_node": (net.deliveries * net.bits_per_delivery).tolist(),
        "dock_center_m": list(sc.dock_center_m),
        "dock_radius_m": sc.dock_radius_m,
        "area_m": list(sc.area_m),
        "slot_s": sc.slot_s,
    }
