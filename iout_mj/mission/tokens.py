"""The token observation of the general policies: one row of features per node, padded to
K_max with a mask, so that a network with shared per-node weights serves any K.

Flat layout, for N AUVs: [global G][AUV tokens N x A][node tokens K_max x F][node mask K_max].
Bearings are relative to each AUV's heading setpoint (what the heading action changes), so a
node straight ahead reads (cos, sin) = (1, 0) wherever it lies. Everything is scaled to about
[-1, 2]; padded nodes are zeros with mask 0. The features the flat observation also has
(positions, speeds, docked, AoI, node energy, distances, time remaining) are its groups, as
the compiled rules scale them (`Mission.observation`); the rest is numpy here. Works on
batched missions.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from iout_mj.types import FloatArray
from iout_mj.world.geometry import unit_xy, wrap_angle

if TYPE_CHECKING:
    from iout_mj.mission.core import Mission

K_MAX = 30
"""Nodes a token observation holds (the config's MAX_NODES)."""
GLOBAL_FEATURES = 3
"""Time remaining, K / K_max, mean AoI / A_max."""
ETA_CRUISE_MPS = 3.0
"""Speed of the docking time estimate (the baselines' cruise speed)."""


def auv_features(n_auvs: int) -> int:
    """Entries of one AUV token: position 2, heading 2, speed 2, docked, dock distance, dock
    bearing 2, docking slack, and distance and bearing of each other AUV."""
    return 11 + 3 * (n_auvs - 1)


def node_features(n_auvs: int) -> int:
    """Entries of one node token: position 2, AoI, K_reset progress, energy, and per AUV its
    distance, bearing 2 and uplink affordability."""
    return 5 + 4 * n_auvs


def token_size(n_auvs: int, k_max: int = K_MAX) -> int:
    """Length of the flat token observation."""
    return GLOBAL_FEATURES + n_auvs * auv_features(n_auvs) + k_max * (node_features(n_auvs) + 1)


def _bearing(delta_m: FloatArray, heading_rad: FloatArray) -> FloatArray:
    """(cos, sin) of the direction of `delta_m` relative to `heading_rad`, (..., 2)."""
    rel = wrap_angle(np.arctan2(delta_m[..., 1], delta_m[..., 0]) - heading_rad)
    return np.stack([np.cos(rel), np.sin(rel)], axis=-1)


def observe_tokens(mission: Mission, k_max: int = K_MAX) -> np.ndarray:
    """The token observation of `mission`, float32 (*batch, token_size(N, k_max))."""
    s, net, cfg = mission.state, mission.network, mission.cfg
    n, k, batch = mission.n_auvs, mission.n_nodes, mission.batch
    if k > k_max:
        raise ValueError(f"{k} nodes do not fit a token observation of {k_max}")
    horizon = cfg.scenario.horizon_slots
    flat = mission.observation()  # the scaled features shared with the flat observation
    left = flat["time_remaining"][..., 0]
    glob = np.stack(np.broadcast_arrays(left, k / k_max, flat["aoi"].mean(axis=-1)), axis=-1)
    heading = s.heading_sp[..., None]  # (*b, N, 1)
    dock_delta = mission.dock_m - s.positions_m
    eta = s.dock_dist_m / (ETA_CRUISE_MPS * cfg.scenario.slot_s) / horizon
    auv = [
        flat["auv_position"].reshape(*batch, n, 2),
        unit_xy(s.heading_sp),
        flat["auv_speed"][..., None],
        (s.speed_sp / cfg.motion.v_max_mps)[..., None],
        flat["docked"][..., None],
        flat["dock_distance"][..., None],
        _bearing(dock_delta, s.heading_sp),
        np.clip(left[..., None] - eta, -1, 1)[..., None],
    ]
    if n > 1:
        delta = s.positions_m[..., None, :, :] - s.positions_m[..., :, None, :]  # (*b, i, j, 2)
        others = ~np.eye(n, dtype=bool)
        d = np.linalg.norm(delta, axis=-1)[..., others].reshape(*batch, n, n - 1)
        b = _bearing(delta, heading)[..., others, :].reshape(*batch, n, n - 1, 2)
        auv.append(np.concatenate([d[..., None] * mission.inv_diag, b], -1).reshape(*batch, n, -1))
    auv_tokens = np.concatenate(auv, axis=-1).reshape(*batch, -1)

    node_delta = net.nodes_m[..., None, :, :] - s.positions_m[..., :, None, :]  # (*b, N, K, 2)
    _, need_j = net.link.energies_j(s.distance_m)  # (*b, N, K)
    afford = np.clip(np.log10(np.maximum(net.energy_j[..., None, :], 1e-12) / need_j) / 3, -1, 2)
    per_auv = np.concatenate(
        [
            flat["distance"].reshape(*batch, n, k, 1),
            _bearing(node_delta, heading),
            afford[..., None],
        ],
        axis=-1,
    )  # (*b, N, K, 4)
    nodes = np.concatenate(
        [
            net.nodes_m * mission.inv_area - 0.5,
            flat["aoi"][..., None],
            (net.service_count / cfg.network.k_reset)[..., None],
            flat["node_energy"][..., None],
            np.moveaxis(per_auv, -3, -2).reshape(*batch, k, -1),
        ],
        axis=-1,
    )
    padded = np.zeros((*batch, k_max, nodes.shape[-1]))
    padded[..., :k, :] = nodes
    mask = np.zeros((*batch, k_max))
    mask[..., :k] = 1.0
    return np.concatenate(
        [glob, auv_tokens, padded.reshape(*batch, -1), mask], axis=-1, dtype=np.float32
    )
