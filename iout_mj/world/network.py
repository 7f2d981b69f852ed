"""Sensor-node state: stored energy, AoI with K_reset, service and delivery counts, Jain (numpy).

Every array may carry leading batch axes: `(*batch, K)` for node state, `(*batch, N, ...)` for
AUV inputs; `batch` is () for one environment and (B,) for B environments stepped together.

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
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from iout_mj.config import AcousticsConfig, NetworkConfig
from iout_mj.types import BoolArray, FloatArray
from iout_mj.world import acoustics
from iout_mj.world.geometry import pairwise_distance_m

INITIAL_AOI = 1.0


def jain_index(counts: ArrayLike) -> Any:
    """Jain's index (sum o)^2 / (K sum o^2) over the last axis; 0 where nothing was delivered."""
    o = np.asarray(counts)
    sq = (o * o).sum(axis=-1)
    return (np.square(o.sum(axis=-1)) / (o.shape[-1] * sq + (sq == 0)))[()]  # 0 / 1 if none


def rows(mask: BoolArray | None) -> Any:
    """Index of the batch rows to (re)set: every row for None, else the rows where `mask`."""
    return Ellipsis if mask is None else mask


@dataclass(frozen=True)
class SlotOutcome:
    """What happened in one slot (leading batch axes omitted below)."""

    distance_m: FloatArray
    """(N, K) AUV-node distances used for the link budget."""
    uplink_ok: BoolArray
    """(N,) the node named by AUV i delivered an update."""
    uplink_req_j: FloatArray
    """(N,) E_req from AUV i's named node to AUV i."""
    uplink_stored_j: FloatArray
    """(N,) energy stored at AUV i's named node at the start of the slot."""
    harvested_j: FloatArray
    """(K,) energy each node harvested in this slot."""
    delivered: BoolArray
    """(K,) node k delivered an update."""


class SensorNetwork:
    """The K nodes' state and its per-slot update, for `batch` independent networks."""

    def __init__(
        self,
        nodes_m: ArrayLike,
        network: NetworkConfig,
        acoustic: AcousticsConfig,
        batch: tuple[int, ...] = (),
    ):
        nodes = np.asarray(nodes_m, dtype=float)
        k = len(nodes)
        self.batch = batch
        self.nodes_m = np.broadcast_to(nodes, (*batch, k, 2)).copy()
        """(*batch, K, 2) node positions (a random layout may differ per environment)."""
        self.cfg = network
        self.acoustic = acoustic
        self.bits_per_delivery = acoustics.bits_per_delivery(acoustic)
        self.link = acoustics.LinkBudget(acoustic)
        self._node_index = np.arange(k)
        self.energy_j = np.zeros((*batch, k))
        self.aoi = np.zeros((*batch, k))
        self.service_count = np.zeros((*batch, k), dtype=np.int64)
        self.deliveries = np.zeros((*batch, k), dtype=np.int64)
        self.reset()

    @property
    def n_nodes(self) -> int:
        return len(self._node_index)

    def reset(self, mask: BoolArray | None = None) -> None:
        """Fresh nodes in every environment (mask None) or in those where `mask` is True."""
        i = rows(mask)
        self.energy_j[i] = self.cfg.node_initial_energy_j
        self.aoi[i] = INITIAL_AOI
        self.service_count[i] = 0
        self.deliveries[i] = 0

    @property
    def delivered_bits(self) -> Any:
        return self.deliveries.sum(axis=-1) * self.bits_per_delivery

    @property
    def jain(self) -> Any:
        return jain_index(self.deliveries)

    @property
    def mean_aoi(self) -> Any:
        return self.aoi.sum(axis=-1) / self.n_nodes

    def step(
        self, auv_xy: ArrayLike, wet_nodes: ArrayLike, data_nodes: ArrayLike, active: ArrayLike
    ) -> SlotOutcome:
        """Advance one slot.

        Args:
            auv_xy: (*batch, N, 2) AUV positions in metres.
            wet_nodes: (*batch, N) node index each AUV charges.
            data_nodes: (*batch, N) node index each AUV collects from.
            active: (*batch, N) bool; inactive (docked) AUVs neither charge nor collect.
        """
        act = np.asarray(active, dtype=bool)[..., None]
        d = pairwise_distance_m(auv_xy, self.nodes_m)
        harvest_all, req_all = self.link.energies_j(d)

        picked = self._node_index == np.asarray(data_nodes)[..., None]  # (*batch, N, K)
        req_node = np.where(picked & act, req_all, np.inf).min(axis=-2)  # inf: not named
        stored = self.energy_j.copy()
        delivered = stored >= req_node
        charged = (self._node_index == np.asarray(wet_nodes)[..., None]) & act
        harvested = np.where(charged, harvest_all, 0.0).sum(axis=-2)

        self.energy_j += harvested - np.where(delivered, req_node, 0.0)
        self.deliveries += delivered
        self.service_count += delivered
        reset = self.service_count >= self.cfg.k_reset
        self.aoi = np.where(reset, INITIAL_AOI, np.minimum(self.aoi + 1, self.cfg.aoi_max))
        self.service_count[reset] = 0
        return SlotOutcome(
            distance_m=d,
            uplink_ok=(picked & delivered[..., None, :]).any(axis=-1) & act[..., 0],
            uplink_req_j=np.where(picked, req_all, 0.0).sum(axis=-1),
            uplink_stored_j=np.where(picked, stored[..., None, :], 0.0).sum(axis=-1),
            harvested_j=harvested,
            delivered=delivered,
        )
