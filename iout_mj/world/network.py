"""Sensor-node state and rules: stored energy, AoI with K_reset, deliveries, Jain (compiled).

Every array may carry leading batch axes: `(*batch, K)` for node state, `(*batch, N, ...)` for
AUV inputs; `batch` is () for one environment and (B,) for B environments stepped together.

Rules of one slot (paper section III-A), for N AUVs and K nodes, compiled in `network.c`
(`iout_serve`, one environment: the mission's compiled slot calls it, `SensorNetwork.step`
loops it over a batch):

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

import ctypes
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from iout_mj import native
from iout_mj.config import AcousticsConfig, NetworkConfig
from iout_mj.types import BoolArray, FloatArray, IntArray
from iout_mj.world import acoustics

INITIAL_AOI = 1.0
"""AoI after a reset and after the K_reset-th delivery (one slot; `network.c` too)."""


def jain_index(counts: ArrayLike) -> Any:
    """Jain's index (sum o)^2 / (K sum o^2) over the last axis; 0 where nothing was
    delivered (the compiled `iout_jain` of the rules)."""
    o = np.ascontiguousarray(counts, dtype=np.int64)
    rows_k = o.reshape(-1, o.shape[-1])
    values = [native.lib.iout_jain(native.address(r), r.size) for r in rows_k]
    return np.array(values).reshape(o.shape[:-1])[()]


def rows(mask: BoolArray | None) -> Any:
    """Index of the batch rows to (re)set: every row for None, else the rows where `mask`."""
    return Ellipsis if mask is None else mask


class NetworkArrays(NamedTuple):
    """The node state of a batch, every array with a leading batch axis (the compiled view)."""

    nodes_m: FloatArray
    energy_j: FloatArray
    aoi: FloatArray
    service_count: IntArray
    deliveries: IntArray
    mean_aoi: FloatArray
    jain: FloatArray


class SlotOutcome(NamedTuple):
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
    """The K nodes' state, for `batch` independent networks (arrays `(*batch, K, ...)`)."""

    def __init__(
        self,
        nodes_m: ArrayLike,
        network: NetworkConfig,
        acoustic: AcousticsConfig,
        batch: tuple[int, ...] = (),
    ):
        nodes = np.asarray(nodes_m, dtype=float)
        k = len(nodes)
        self.batch, self.n_nodes = batch, k
        self.cfg = network
        self.acoustic = acoustic
        self.bits_per_delivery = acoustics.bits_per_delivery(acoustic)
        self.link = acoustics.LinkBudget(acoustic)
        self.nodes_m = np.broadcast_to(nodes, (*batch, k, 2)).copy()
        """(*batch, K, 2) node positions (a random layout may differ per environment)."""
        self.energy_j = np.zeros((*batch, k))
        self.aoi = np.zeros((*batch, k))
        self.service_count = np.zeros((*batch, k), dtype=np.int64)
        self.deliveries = np.zeros((*batch, k), dtype=np.int64)
        self.mean_aoi = np.zeros(batch)
        """(*batch,) mean AoI over the nodes (kept by the rules)."""
        self.jain = np.zeros(batch)
        """(*batch,) Jain's index of the deliveries (kept by the rules)."""
        self._bind()
        self.reset()

    def _bind(self) -> None:
        """The arrays with a batch axis always (one env: of one) and their C view (`Network`
        in native.h; rebuilt after unpickling: it holds addresses)."""
        one = () if self.batch else (None,)
        self.arrays = NetworkArrays(*(getattr(self, f)[one] for f in NetworkArrays._fields))
        self.struct = NETWORK_STRUCT()
        native.fill(self.struct, self.arrays)

    def __getstate__(self) -> dict[str, Any]:
        return {k: v for k, v in self.__dict__.items() if k not in ("arrays", "struct")}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._bind()

    def reset(self, mask: BoolArray | None = None) -> None:
        """Fresh nodes in every environment (mask None) or in those where `mask` is True."""
        i = rows(mask)
        self.energy_j[i] = self.cfg.node_initial_energy_j
        self.aoi[i] = INITIAL_AOI
        self.service_count[i] = 0
        self.deliveries[i] = 0
        native.lib.iout_summarise(ctypes.addressof(self.struct), len(self.arrays.aoi), self.n_nodes)

    @property
    def delivered_bits(self) -> Any:
        return self.deliveries.sum(axis=-1) * self.bits_per_delivery

    def step(
        self, auv_xy: ArrayLike, wet_nodes: ArrayLike, data_nodes: ArrayLike, active: ArrayLike
    ) -> SlotOutcome:
        """Advance one slot of every network (the rules of `serve`).

        Args:
            auv_xy: (*batch, N, 2) AUV positions in metres.
            wet_nodes: (*batch, N) node index each AUV charges.
            data_nodes: (*batch, N) node index each AUV collects from.
            active: (*batch, N) bool; inactive (docked) AUVs neither charge nor collect.
        """
        b = self.batch or (1,)
        xy = np.ascontiguousarray(auv_xy, dtype=float).reshape(*b, -1, 2)
        n, k = xy.shape[-2], self.n_nodes
        wet = np.ascontiguousarray(wet_nodes, dtype=np.int64).reshape(*b, n)
        data = np.ascontiguousarray(data_nodes, dtype=np.int64).reshape(*b, n)
        act = np.ascontiguousarray(active, dtype=bool).reshape(*b, n)
        if ((wet < 0) | (wet >= k) | (data < 0) | (data >= k)).any():
            raise ValueError(f"node indices {wet.tolist()}, {data.tolist()}: accepted 0 to {k - 1}")
        out = SlotOutcome(
            np.zeros((*b, n, k)),
            np.zeros((*b, n), dtype=bool),
            np.zeros((*b, n)),
            np.zeros((*b, n)),
            np.zeros((*b, k)),
            np.zeros((*b, k), dtype=bool),
        )
        for e in range(b[0]):
            native.lib.iout_serve(
                ctypes.addressof(self.struct),
                e,
                n,
                k,
                native.address(self.link.constants),
                self.cfg.k_reset,
                self.cfg.aoi_max,
                *(native.address(x[e]) for x in (xy, wet, data)),
                1,
                native.address(act[e]),
                *(native.address(x[e]) for x in out),
            )
        return out if self.batch else SlotOutcome(*(x[0] for x in out))


NETWORK_STRUCT = native.pointers("Network", NetworkArrays._fields)
"""`Network` of native.h: one pointer per array of `NetworkArrays`, in order."""
