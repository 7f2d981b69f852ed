"""The observation, declared once: name, size, scaling and range of every group, in order.

The paper's state is positions, headings, speeds, AoI, node energies and distances; docked,
dock distance and remaining time are added because the docking deadline makes them part of
the Markov state. `OBSERVATION_DOC` (the env's docstring and the README) is made from here;
the compiled `mission.rules.observe` writes the groups in this order.
"""

from __future__ import annotations

from collections.abc import Callable
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
    native.lib.iout_node_energy_levels(
        native.address(e), e.size, ENERGY_OBS_REF_J, OBS_HIGH, native.address(out)
    )
    return out


@dataclass(frozen=True)
class ObservationGroup:
    name: str
    size_text: str
    """Entries in terms of N and K, as the docs write it."""
    size: Callable[[int, int], int]
    """Entries for (N, K)."""
    doc: str
    bounds: str


OBSERVATION_LAYOUT: tuple[ObservationGroup, ...] = (
    ObservationGroup(
        "auv_position",
        "2N",
        lambda n, k: 2 * n,
        "(x, y) / area side",
        "[0, 1]",
    ),
    ObservationGroup(
        "auv_heading",
        "2N",
        lambda n, k: 2 * n,
        "(cos, sin) of the measured heading",
        "[-1, 1]",
    ),
    ObservationGroup(
        "auv_speed",
        "N",
        lambda n, k: n,
        "measured speed over ground / V_max",
        "[0, ~1]",
    ),
    ObservationGroup(
        "docked",
        "N",
        lambda n, k: n,
        "1 once docked",
        "{0, 1}",
    ),
    ObservationGroup(
        "aoi",
        "K",
        lambda n, k: k,
        "AoI / A_max",
        "(0, 1]",
    ),
    ObservationGroup(
        "node_energy",
        "K",
        lambda n, k: k,
        "log10(1 + e / 1 mJ) / 5",
        "[0, ~1]",
    ),
    ObservationGroup(
        "distance",
        "N*K",
        lambda n, k: n * k,
        "AUV-node distance / area diagonal",
        "[0, 1]",
    ),
    ObservationGroup(
        "dock_distance",
        "N",
        lambda n, k: n,
        "distance to dock centre / diagonal",
        "[0, 1]",
    ),
    ObservationGroup(
        "time_remaining",
        "1",
        lambda n, k: 1,
        "1 - slot / T_max",
        "[0, 1]",
    ),
)


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
    + (__doc__ or "").split("\n\n")[1].split(" `OBSERVATION_DOC`")[0]
    + "\n"
)
