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
5. Delivered bits: R * tau_data per delivery (`node_bits`, per node).

The acoustic network layer (`config.ChannelConfig.features`; none: the rules above, bit for
bit) changes 1, 2 and 5, in `network.c` (`serve_channel`):

- depth: ranges are slant, sqrt(horizontal^2 + (node depth - AUV depth)^2), in every link
  budget (AET, uplink) and in the observation's distances.
- propagation: the handshake is a poll from the AUV, the node's packets back to back, and one
  block acknowledgement from the AUV: `handshake_legs` (3) one-way travels d/c, with c from
  Mackenzie (1981), so the node transmits for the window tau_data - legs d / c (none if <= 0)
  at the range d of its reference AUV (the nearest active one naming it, whose E_req sets its
  power), and pays E_req (its power) times that window, if its stored energy covers it.
- SINR: a node's power gives SNR = gamma_req = 2^(R/B) - 1 at its reference AUV, so an AUV at
  range d receives gamma_req E_req(d_ref) / E_req(d) times the band's noise, times the link's
  gain (fading). With interference, every other node transmitting in the slot adds its power
  at that AUV to the noise (all uplinks share the data band). The AET does not: its 70 kHz
  tone lies 20 kHz outside the 1 kHz band at 50 kHz that the receiver filters (the config
  refuses interference when the AET falls inside the data band).
- packets: the node sends floor(R window / L) packets of L bits; each reaches the network
  unless every active AUV naming the node loses it, P = 1 - prod PER_i, with PER = 1 - (1 -
  BER)^L and the modulation's BER at Eb/N0 = SINR B / R; the count that arrives is one
  binomial draw. No retransmission: the block acknowledgement tells the node what arrived, and
  what was lost is not resent (the next uplink carries a fresher sample). The update counts as
  a delivery (C_k += 1, AoI) when at least max(1, ceil(delivery_share x sent)) packets arrive;
  delivered bits are L per packet that arrived. Without packets, the Shannon bound: delivered
  when some AUV's SINR reaches gamma_req, R x window bits.
- fading: each link (AUV, transmitting node) gets a power gain per slot (block fading; an AUV
  moves up to 100 m in a slot, far beyond the decorrelation distance): Rician with K (0:
  Rayleigh), unit mean, times log-normal shadowing 10^(sigma z / 10).

Randomness: C draws nothing; `Mission` fills IOUT_CHANNEL_DRAWS(N) uniforms per AUV before each
slot from the task RNG (only with packets or fading on), so runs stay seeded and resumable.
"""

from __future__ import annotations

import ctypes
from collections import namedtuple
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from iout_mj import native
from iout_mj.config import AcousticsConfig, ChannelConfig, NetworkConfig
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
    "node_bits": np.dtype(float),
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
        channel: ChannelConfig | None = None,
    ):
        nodes = np.asarray(nodes_m, dtype=float)
        k = len(nodes)
        self.batch, self.n_nodes = batch, k
        self.cfg = network
        self.acoustic = acoustic
        self.bits_per_delivery = acoustics.bits_per_delivery(acoustic)
        channel = channel or ChannelConfig()
        self.channel_config = channel
        """The channel's config (its depths: `ChannelConfig.depths_m`)."""
        self.link = acoustics.LinkBudget(acoustic, channel)
        self.channel = acoustics.ChannelConstants(channel, acoustic)
        """The channel's constants (every feature off by default: the paper's channel)."""
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
        self.node_bits = native.allocate((*batch, k), float)
        """(*batch, K) bits delivered by each node so far (kept by the rules)."""
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
        self.node_bits[i] = 0.0
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
        """(*batch,) bits delivered by all nodes so far."""
        return self.node_bits.sum(axis=-1)
