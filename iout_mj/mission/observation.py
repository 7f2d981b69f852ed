"""The observation: every group's name, size, scaling and range, in order.

The paper's state is positions, headings, speeds, AoI, node energies and distances; docked,
dock distance and remaining time are added because the docking deadline makes them part of
the Markov state.

The groups, their order and sizes are declared once in `native.h` (IOUT_OBSERVATION, which
also orders the C functions that write them); this module adds each group's documentation
(checked at import to cover exactly those groups) and makes `OBSERVATION_DOC` (the env's
docstring and the README) from both.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from iout_mj import native
from iout_mj.types import FloatArray

OBS_LOW, OBS_HIGH = -1.0, 2.0
"""Bounds of every observation entry (node energy is clipped to the top)."""
ENERGY_OBS_REF_J = 1e-3
"""Node energies are observed as log10(1 + e / 1 mJ) / 5 (1 mJ is a typical uplink need)."""


def node_energy_level(energy_j: Any) -> FloatArray:
    """The observed node energy, log10(1 + e / 1 mJ) / 5, clipped to OBS_HIGH, of each entry
    (the compiled `iout_node_energy_level` of the observation; also the renderer's node size)."""
    e = np.ascontiguousarray(energy_j, dtype=float)
    out = np.empty_like(e)
    native.call(
        native.lib.iout_node_energy_levels,
        native.address(e),
        e.size,
        ENERGY_OBS_REF_J,
        OBS_HIGH,
        native.address(out),
    )
    return out


@dataclass(frozen=True)
class ObservationGroup:
    name: str
    sizes: native.Group
    """Entries per AUV, per node, per AUV-node pair and fixed (native.h)."""
    doc: str
    bounds: str

    def size(self, n_auvs: int, n_nodes: int) -> int:
        """Entries for N AUVs and K nodes."""
        g = self.sizes
        return g.per_auv * n_auvs + g.per_node * n_nodes + g.per_pair * n_auvs * n_nodes + g.fixed

    @property
    def size_text(self) -> str:
        """Entries in terms of N and K, as the docs write it."""
        g = self.sizes
        parts = [
            f"{c if c != 1 else ''}{unit}"
            for c, unit in ((g.per_auv, "N"), (g.per_node, "K"), (g.per_pair, "N*K"))
            if c
        ]
        return " + ".join(parts + ([str(g.fixed)] if g.fixed or not parts else []))


_DOCS = {
    "auv_position": ("(x, y) / area side", "[0, 1]"),
    "auv_heading": ("(cos, sin) of the measured heading", "[-1, 1]"),
    "auv_speed": ("measured speed over ground / V_max", "[0, ~1], clipped at 2"),
    "docked": ("1 once docked", "{0, 1}"),
    "aoi": ("AoI / A_max", "(0, 1]"),
    "node_energy": ("log10(1 + e / 1 mJ) / 5", "[0, ~1], clipped at 2"),
    "distance": ("AUV-node distance / area diagonal", "[0, 1]"),
    "dock_distance": ("distance to dock centre / diagonal", "[0, 1]"),
    "time_remaining": ("1 - slot / T_max", "[0, 1]"),
}
native.require_names(
    "the observation groups (documented in mission/observation.py)",
    tuple(g.name for g in native.GROUPS),
    tuple(_DOCS),
)
OBSERVATION_LAYOUT: tuple[ObservationGroup, ...] = tuple(
    ObservationGroup(g.name, g, *_DOCS[g.name]) for g in native.GROUPS
)
"""The observation groups in order: the library's declaration with their documentation."""


def split_observation(flat: FloatArray, n_auvs: int, n_nodes: int) -> dict[str, FloatArray]:
    """A flat observation (..., D) as its groups, in order (views)."""
    sizes = observation_sizes(n_auvs, n_nodes).values()
    ends = np.cumsum(list(sizes))
    return {
        g.name: flat[..., end - size : end]
        for g, size, end in zip(OBSERVATION_LAYOUT, sizes, ends, strict=True)
    }


def observation_sizes(n_auvs: int, n_nodes: int) -> dict[str, int]:
    """Entries of every group for N AUVs and K nodes."""
    return {g.name: g.size(n_auvs, n_nodes) for g in OBSERVATION_LAYOUT}


def flatten_observation(obs: dict[str, Any]) -> np.ndarray:
    """An observation dict concatenated in its declared order, as float32 (..., D)."""
    return np.concatenate(list(obs.values()), axis=-1, dtype=np.float32)


OBSERVATION_DOC = (
    "Observation (flattened in this order; N AUVs, K nodes):\n"
    + "".join(
        f"  {g.name:<15}{g.size_text:>3}  {g.doc:<38} {g.bounds}\n" for g in OBSERVATION_LAYOUT
    )
    + (__doc__ or "").split("\n\n")[1]
    + "\n"
)
