"""Episode statistics: the metrics, the trace, and the one episode summary."""

from __future__ import annotations

from typing import Any

import numpy as np

from iout_mj.config import Config
from iout_mj.mission.state import MissionLog, MissionState
from iout_mj.world.network import SensorNetwork


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
        "jain": float(net.jain[i]),
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


def trace(cfg: Config, log: MissionLog, net: SensorNetwork, slot: int) -> dict[str, Any]:
    """The episode's path and service after `slot` slots, as plain lists (for figures and
    JSON; one env)."""
    sc = cfg.scenario
    return {
        "positions_m": log.positions_m[: slot + 1].tolist(),
        "headings_rad": log.headings_rad[: slot + 1].tolist(),
        "speeds_mps": log.speeds_mps[: slot + 1].tolist(),
        "nodes_m": net.nodes_m.tolist(),
        "delivered_bits_per_node": net.node_bits.tolist(),
        "dock_center_m": list(sc.dock_center_m),
        "dock_radius_m": sc.dock_radius_m,
        "area_m": list(sc.area_m),
        "slot_s": sc.slot_s,
    }
