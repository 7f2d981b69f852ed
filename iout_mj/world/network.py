"""Sensor-node state and rules: stored energy, AoI with K_reset, deliveries, Jain (compiled).

Every array may carry leading batch axes: `(*batch, K)` for node state, `(*batch, N, ...)` for
AUV inputs; `batch` is () for one environment and (B,) for B environments stepped together.

Rules of one slot (paper section III-A), for N AUVs and K nodes, compiled in `network.c`
(`iout_serve_env`, which the mission's compiled slot calls for each environment):

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
from collections import namedtuple
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from iout_mj import native
from iout_mj.config import AcousticsConfig, NetworkConfig
from iout_mj.types import BoolArray
from iout_mj.world import acoustics

INITIAL_AOI = 1.0
"""AoI after a reset and after the K_reset-th delivery (one slot; `network.c` too)."""


def rows(mask: BoolArray | None) -> Any:
    """Index of the batch rows to (re)set: every row for None, else the rows where `mask`."""
    return Ellipsis if mask is None else mask


NETWORK_DTYPES = {
    "nodes_m": np.dtype(float),
    "energy_j": np.dtype(float),
    "aoi": np.dtype(float),
    "service_count": np.dtype(np.int64),
    "deliveries": np.dtype(np.int64),
    "mean_aoi": np.dtype(float),
    "jain": np.dtype(float),
}
"""The node state's arrays and element types (native.h's IOUT_NETWORK, checked at import)."""
native.require_fields("Network", NETWORK_DTYPES)
NetworkArrays = namedtuple("NetworkArrays", list(NETWORK_DTYPES))  # type: ignore[misc]
"""The node state of a batch, every array with a leading batch axis (the compiled view)."""


class SensorNetwork(native.Frozen):
    """The K nodes' state, for `batch` independent networks (arrays `(*batch, K, ...)`); the
    compiled rules point into its arrays, so they are written in place, never rebound."""

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
        self.nodes_m = native.allocate((*batch, k, 2), float)
        """(*batch, K, 2) node positions (a random layout may differ per environment)."""
        self.nodes_m[...] = nodes
        self.energy_j = native.allocate((*batch, k), float)
        self.aoi = native.allocate((*batch, k), float)
        self.service_count = native.allocate((*batch, k), np.int64)
        self.deliveries = native.allocate((*batch, k), np.int64)
        self.mean_aoi = native.allocate(batch, float)
        """(*batch,) mean AoI over the nodes (kept by the rules)."""
        self.jain = native.allocate(batch, float)
        """(*batch,) Jain's index of the deliveries (kept by the rules)."""
        self._bind()
        self._freeze()
        self.reset()

    def _bind(self) -> None:
        """The arrays with a batch axis always (one env: of one) and their C view (`Network`
        in native.h; rebuilt after unpickling: it holds addresses)."""
        one = () if self.batch else (None,)
        self._arrays: Any = NetworkArrays(*(getattr(self, f)[one] for f in NETWORK_DTYPES))
        self._struct = native.struct_type("Network")()
        native.fill(self._struct, self._arrays)

    def __getstate__(self) -> dict[str, Any]:
        return {k: v for k, v in self.__dict__.items() if k not in ("_arrays", "_struct")}

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
        self.summarise()

    def summarise(self) -> None:
        """Recompute the mean AoI and Jain's index of every network from its arrays."""
        native.call(
            native.lib.iout_summarise,
            ctypes.addressof(self._struct),
            len(self._arrays.aoi),
            self.n_nodes,
        )

    @property
    def delivered_bits(self) -> Any:
        return self.deliveries.sum(axis=-1) * self.bits_per_delivery
