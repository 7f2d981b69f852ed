"""One AUV's own view of the mission, for decentralised policies: the token observation
(`mission.tokens`) as that AUV sees it, padded to n_max AUVs and k_max nodes.

    global G | own AUV token's fixed entries | per other-AUV slot (n_max - 1): the AUV token's
    per-other entries, that AUV's docked flag, present | per node slot (k_max): the node
    token's fixed entries, its link entries for this AUV, present | one-hot index n_max

So an AUV knows the clock, its own pose, setpoints, dock bearing and docking slack, where the
other AUVs are relative to it, and per node its position, AoI, reset progress, stored energy
and its own link to it (distance, bearing relative to its heading setpoint, energy ratio): no
other AUV's link, heading or intention. Absent slots are zeros with present = 0. Every entry
follows from native.h's IOUT_TOKENS declaration; the PettingZoo env's agent observation is this
view at its own sizes (n_max = N, k_max = K).
"""

from __future__ import annotations

from functools import cache

import numpy as np

from iout_mj import native
from iout_mj.mission.core import Mission
from iout_mj.mission.tokens import GLOBAL_FEATURES, auv_features, node_features


@cache
def _columns(part: str, others: int) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    """Within one token of `part` with `others` per-AUV blocks: the columns of its fixed
    entries, the (others, per) columns of its per-AUV entries, and each fixed entry's first
    column."""
    fixed: list[int] = []
    per: list[list[int]] = [[] for _ in range(others)]
    first: dict[str, int] = {}
    at = 0
    for t in native.TOKENS:
        if t.part != part:
            continue
        first[t.name] = at
        fixed += range(at, at + t.fixed)
        at += t.fixed
        for m in range(others):
            per[m] += range(at + m * t.per_auv, at + (m + 1) * t.per_auv)
        at += t.per_auv * others
    width = sum(t.per_auv for t in native.TOKENS if t.part == part)
    return np.array(fixed), np.array(per, dtype=np.int64).reshape(others, width), first


@cache
def _others(n: int) -> np.ndarray:
    """(n, n - 1): for each AUV, the other AUVs' indices in order (the AUV token's order)."""
    rest = [[j for j in range(n) if j != i] for i in range(n)]
    return np.array(rest, dtype=np.int64).reshape(n, n - 1)


OWN_FEATURES = len(_columns("auv", 0)[0])
"""The AUV token's fixed entries."""
OTHER_FEATURES = _columns("auv", 1)[1].shape[1] + 2
"""Per other AUV: the AUV token's per-other entries, its docked flag, present."""
NODE_FEATURES = len(_columns("node", 0)[0]) + _columns("node", 1)[1].shape[1] + 1
"""Per node: the node token's fixed entries, its per-AUV entries for this AUV, present."""


def agent_observation_size(n_max: int, k_max: int) -> int:
    """Entries of one AUV's view padded to n_max AUVs and k_max nodes."""
    return (
        GLOBAL_FEATURES
        + OWN_FEATURES
        + OTHER_FEATURES * (n_max - 1)
        + NODE_FEATURES * k_max
        + n_max
    )


def node_present_slice(n_max: int, k_max: int) -> slice:
    """Where the node-present flags lie in a padded view (one per node slot)."""
    start = GLOBAL_FEATURES + OWN_FEATURES + OTHER_FEATURES * (n_max - 1)
    return slice(start + NODE_FEATURES - 1, start + NODE_FEATURES * k_max, NODE_FEATURES)


def agent_observations(
    m: Mission, n_max: int | None = None, k_max: int | None = None
) -> np.ndarray:
    """(N, agent_observation_size(n_max, k_max)) float32: every AUV's own view (see the module
    docstring), padded to n_max AUVs and k_max nodes (default: the mission's N and K)."""
    n, k = m.n_auvs, m.n_nodes
    n_max, k_max = n_max or n, k_max or k
    if not (1 <= n <= n_max and 1 <= k <= k_max):
        raise ValueError(f"a view padded to N={n_max}, K={k_max} cannot hold N={n}, K={k}")
    tokens = m.observe_tokens(k_max=k)
    a_size, n_size = auv_features(n), node_features(n)
    auv_at = GLOBAL_FEATURES
    node_at = auv_at + n * a_size
    auv = tokens[auv_at:node_at].reshape(n, a_size)
    node = tokens[node_at : node_at + k * n_size].reshape(k, n_size)
    own_cols, other_cols, first = _columns("auv", n - 1)
    node_fixed, node_links, _ = _columns("node", n)

    out = np.zeros((n, agent_observation_size(n_max, k_max)), dtype=np.float32)
    out[:, :GLOBAL_FEATURES] = tokens[:GLOBAL_FEATURES]
    at = GLOBAL_FEATURES
    out[:, at : at + OWN_FEATURES] = auv[:, own_cols]
    at += OWN_FEATURES
    others = out[:, at : at + OTHER_FEATURES * (n_max - 1)].reshape(n, n_max - 1, OTHER_FEATURES)
    per_other = other_cols.shape[1]
    others[:, : n - 1, :per_other] = auv[:, other_cols]
    others[:, : n - 1, per_other] = auv[_others(n), first["docked"]]
    others[:, : n - 1, per_other + 1] = 1.0
    at += OTHER_FEATURES * (n_max - 1)
    nodes = out[:, at : at + NODE_FEATURES * k_max].reshape(n, k_max, NODE_FEATURES)
    n_fixed = len(node_fixed)
    nodes[:, :k, :n_fixed] = node[:, node_fixed]
    nodes[:, :k, n_fixed:-1] = node[:, node_links].transpose(1, 0, 2)
    nodes[:, :k, -1] = 1.0
    at += NODE_FEATURES * k_max
    out[:, at : at + n] = np.eye(n, dtype=np.float32)
    return out
