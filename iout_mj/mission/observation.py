"""The observation, declared once: name, size, scaling and range of every group, in order.

The paper's state is positions, headings, speeds, AoI, node energies and distances; docked,
dock distance and remaining time are added because the docking deadline makes them part of
the Markov state. `OBSERVATION_DOC` (the env's docstring and the README) is made from here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from iout_mj.types import FloatArray
from iout_mj.world.geometry import unit_xy

if TYPE_CHECKING:  # the mission imports this module; only the annotation needs it
    from iout_mj.mission.core import Mission

OBS_LOW, OBS_HIGH = -1.0, 2.0
"""Bounds of every observation entry (node energy is clipped to the top)."""
ENERGY_OBS_REF_J = 1e-3
"""Node energies are observed as log10(1 + e / 1 mJ) / 5 (1 mJ is a typical uplink need)."""


def node_energy_level(energy_j: FloatArray) -> FloatArray:
    """The observed node energy, log10(1 + e / 1 mJ) / 5, clipped to OBS_HIGH (also the
    renderer's node size)."""
    return np.minimum(np.log10(1 + energy_j / ENERGY_OBS_REF_J) / 5, OBS_HIGH)


@dataclass(frozen=True)
class ObservationGroup:
    name: str
    size_text: str
    """Entries in terms of N and K, as the docs write it."""
    size: Callable[[int, int], int]
    """Entries for (N, K)."""
    value: Callable[[Mission], FloatArray]
    """The group's entries, (*batch, size)."""
    doc: str
    bounds: str


def _flat(m: Mission, x: FloatArray) -> FloatArray:
    return x.reshape(*m.batch, -1)


OBSERVATION_LAYOUT: tuple[ObservationGroup, ...] = (
    ObservationGroup(
        "auv_position",
        "2N",
        lambda n, k: 2 * n,
        lambda m: _flat(m, m.state.positions_m * m.inv_area),
        "(x, y) / area side",
        "[0, 1]",
    ),
    ObservationGroup(
        "auv_heading",
        "2N",
        lambda n, k: 2 * n,
        lambda m: _flat(m, unit_xy(m.state.headings_rad)),
        "(cos, sin) of the measured heading",
        "[-1, 1]",
    ),
    ObservationGroup(
        "auv_speed",
        "N",
        lambda n, k: n,
        lambda m: m.state.speeds_mps / m.cfg.motion.v_max_mps,
        "measured speed over ground / V_max",
        "[0, ~1]",
    ),
    ObservationGroup(
        "docked",
        "N",
        lambda n, k: n,
        lambda m: m.state.docked.astype(float),
        "1 once docked",
        "{0, 1}",
    ),
    ObservationGroup(
        "aoi",
        "K",
        lambda n, k: k,
        lambda m: m.network.aoi / m.cfg.network.aoi_max,
        "AoI / A_max",
        "(0, 1]",
    ),
    ObservationGroup(
        "node_energy",
        "K",
        lambda n, k: k,
        lambda m: node_energy_level(m.network.energy_j),
        "log10(1 + e / 1 mJ) / 5",
        "[0, ~1]",
    ),
    ObservationGroup(
        "distance",
        "N*K",
        lambda n, k: n * k,
        lambda m: _flat(m, m.state.distance_m * m.inv_diag),
        "AUV-node distance / area diagonal",
        "[0, 1]",
    ),
    ObservationGroup(
        "dock_distance",
        "N",
        lambda n, k: n,
        lambda m: m.state.dock_dist_m * m.inv_diag,
        "distance to dock centre / diagonal",
        "[0, 1]",
    ),
    ObservationGroup(
        "time_remaining",
        "1",
        lambda n, k: 1,
        lambda m: (1 - m.state.slot / m.cfg.scenario.horizon_slots)[..., None],
        "1 - slot / T_max",
        "[0, 1]",
    ),
)


def observe(mission: Mission) -> dict[str, FloatArray]:
    """Every group of the observation, in order."""
    return {g.name: g.value(mission) for g in OBSERVATION_LAYOUT}


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
