"""Sensor-node state: stored energy, AoI with K_reset, service and delivery counts, Jain (numpy).

Rules of one slot (paper section III-A), for N AUVs and K nodes, all vectorised:

1. Distances are taken between the AUV positions given to `step` and the nodes.
2. Uplink: every active AUV names one node. A node named by several AUVs transmits once, with
   the power needed to reach the nearest of them (an acoustic broadcast is heard by all), and
   that counts as one delivery. Energy causality (12f): the node transmits only if the energy
   it stored at the start of the slot covers E_req, and then pays E_req.
3. AET: every active AUV charges one node; harvests from several AUVs add up.
4. AoI (eqs. 8-9): C_k grows by one per delivery and is otherwise unchanged (a failed or absent
   delivery does not clear it, as the paper's equation states); A_k resets to 1 when C_k reaches
   K_reset (and C_k restarts at 0), else A_k = min(A_k + 1, A_max).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from iout_mj import acoustics
from iout_mj.config import AcousticsConfig, NetworkConfig

FloatArray = NDArray[np.float64]
INITIAL_AOI = 1.0


def jain_index(counts: ArrayLike) -> float:
    """Jain's index (sum o)^2 / (K sum o^2); 0 when nothing was delivered (no service)."""
    o = np.asarray(counts, dtype=float)
    sq = float(np.dot(o, o))
    return 0.0 if sq == 0 else float(o.sum() ** 2 / (o.size * sq))


def pairwise_distance_m(auv_xy: ArrayLike, nodes_xy: ArrayLike) -> FloatArray:
    """Distances (N, K) between N AUV positions and K node positions."""
    diff = np.asarray(auv_xy, dtype=float)[:, None, :] - np.asarray(nodes_xy, dtype=float)[None]
    return np.hypot(diff[..., 0], diff[..., 1])


@dataclass(frozen=True)
class SlotOutcome:
    """What happened in one slot."""

    distance_m: FloatArray
    """(N, K) AUV-node distances used for the link budget."""
    uplink_ok: NDArray[np.bool_]
    """(N,) the node named by AUV i delivered an update."""
    uplink_req_j: FloatArray
    """(N,) E_req from AUV i's named node to AUV i."""
    uplink_stored_j: FloatArray
    """(N,) energy stored at AUV i's named node at the start of the slot."""
    harvested_j: FloatArray
    """(K,) energy each node harvested in this slot."""
    delivered: NDArray[np.bool_]
    """(K,) node k delivered an update."""


class SensorNetwork:
    """The K nodes' state and its per-slot update."""

    def __init__(self, nodes_m: ArrayLike, network: NetworkConfig, acoustic: AcousticsConfig):
        self.nodes_m = np.asarray(nodes_m, dtype=float)
        self.cfg = network
        self.acoustic = acoustic
        self.bits_per_delivery = acoustics.bits_per_delivery(acoustic)
        self.link = acoustics.LinkBudget(acoustic)
        k = len(self.nodes_m)
        self.energy_j = np.zeros(k)
        self.aoi = np.zeros(k)
        self.service_count = np.zeros(k, dtype=np.int64)
        self.deliveries = np.zeros(k, dtype=np.int64)
        self.reset()

    @property
    def n_nodes(self) -> int:
        return len(self.nodes_m)

    def reset(self) -> None:
        self.energy_j[:] = self.cfg.node_initial_energy_j
        self.aoi[:] = INITIAL_AOI
        self.service_count[:] = 0
        self.deliveries[:] = 0

    @property
    def delivered_bits(self) -> float:
        return float(self.deliveries.sum()) * self.bits_per_delivery

    @property
    def jain(self) -> float:
        return jain_index(self.deliveries)

    @property
    def mean_aoi(self) -> float:
        return float(self.aoi.mean())

    def step(
        self, auv_xy: ArrayLike, wet_nodes: ArrayLike, data_nodes: ArrayLike, active: ArrayLike
    ) -> SlotOutcome:
        """Advance one slot.

        Args:
            auv_xy: (N, 2) AUV positions in metres.
            wet_nodes: (N,) node index each AUV charges.
            data_nodes: (N,) node index each AUV collects from.
            active: (N,) bool; inactive (docked) AUVs neither charge nor collect.
        """
        k = self.n_nodes
        wet = np.asarray(wet_nodes, dtype=np.int64)
        data = np.asarray(data_nodes, dtype=np.int64)
        act = np.asarray(active, dtype=bool)
        n_idx = np.arange(len(data))
        d = pairwise_distance_m(auv_xy, self.nodes_m)
        harvest_all, req_all = self.link.energies_j(d)

        named = (np.arange(k)[None, :] == data[:, None]) & act[:, None]
        req_node = np.where(named, req_all, np.inf).min(axis=0)
        stored = self.energy_j.copy()
        delivered = np.isfinite(req_node) & (stored >= req_node)
        charged = (np.arange(k)[None, :] == wet[:, None]) & act[:, None]
        harvested = np.where(charged, harvest_all, 0.0).sum(axis=0)

        self.energy_j += harvested - np.where(delivered, req_node, 0.0)
        self.deliveries += delivered
        self.service_count += delivered
        reset = self.service_count >= self.cfg.k_reset
        self.aoi = np.where(reset, INITIAL_AOI, np.minimum(self.aoi + 1, self.cfg.aoi_max))
        self.service_count[reset] = 0
        return SlotOutcome(
            distance_m=d,
            uplink_ok=delivered[data] & act,
            uplink_req_j=req_all[n_idx, data],
            uplink_stored_j=stored[data],
            harvested_j=harvested,
            delivered=delivered,
        )
