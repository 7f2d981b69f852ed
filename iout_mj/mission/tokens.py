"""The token observation of the general policies: one row of features per node, padded to
K_max with a mask, so that a network with shared per-node weights serves any K.

Flat layout, for N AUVs: [global G][AUV tokens N x A][node tokens K_max x F][node mask K_max].
Bearings are relative to each AUV's heading setpoint (what the heading action changes), so a
node straight ahead reads (cos, sin) = (1, 0) wherever it lies. Everything is scaled to about
[-1, 2]; padded nodes are zeros with mask 0. The compiled rules write it
(`Mission.observe_tokens`, `mission/tokens.c`), entry by entry as native.h's IOUT_TOKENS
declares them; `TOKEN_DOCS` documents each, and the sizes below follow from the declaration.
"""

from __future__ import annotations

from functools import cache

from iout_mj import native

K_MAX = 30
"""Nodes a token observation holds (the config's MAX_NODES)."""
ETA_CRUISE_MPS = 3.0
"""Speed of the docking time estimate (the baselines' cruise speed)."""

TOKEN_DOCS = {
    "global.time_remaining": "1 - slot / T_max",
    "global.node_share": "K / K_max",
    "global.mean_aoi": "mean AoI / A_max",
    "auv.position": "(x, y) / area side",
    "auv.heading_setpoint": "(cos, sin) of the heading setpoint",
    "auv.speed": "speed over ground / V_max, clipped at 2",
    "auv.speed_setpoint": "speed setpoint / V_max",
    "auv.docked": "1 once docked",
    "auv.dock_distance": "distance to the dock centre / diagonal",
    "auv.dock_bearing": "(cos, sin) of the dock's bearing",
    "auv.docking_slack": "time remaining - dock distance / (3 m/s T_max slot), in [-1, 1]",
    "auv.other_auvs": "per other AUV: distance / diagonal, (cos, sin) of its bearing",
    "node.position": "(x, y) / area side - 0.5",
    "node.aoi": "AoI / A_max",
    "node.reset_progress": "deliveries since the last AoI reset / K_reset",
    "node.energy": "log10(1 + e / 1 mJ) / 5, clipped at 2",
    "node.auv_links": "per AUV: distance / diagonal, (cos, sin) of the node's bearing, "
    "log10(stored energy / E_req) / 3 in [-1, 2]",
}
native.require_names(
    "the token entries (documented in mission/tokens.py)",
    tuple(f"{t.part}.{t.name}" for t in native.TOKENS),
    tuple(TOKEN_DOCS),
)


@cache
def _part_size(part: str, others: int) -> int:
    return sum(t.fixed + t.per_auv * others for t in native.TOKENS if t.part == part)


GLOBAL_FEATURES = _part_size("global", 0)
"""Entries of the global part."""


def auv_features(n_auvs: int) -> int:
    """Entries of one AUV token."""
    return _part_size("auv", n_auvs - 1)


def node_features(n_auvs: int) -> int:
    """Entries of one node token."""
    return _part_size("node", n_auvs)


def token_size(n_auvs: int, k_max: int = K_MAX) -> int:
    """Length of the flat token observation."""
    return GLOBAL_FEATURES + n_auvs * auv_features(n_auvs) + k_max * (node_features(n_auvs) + 1)
