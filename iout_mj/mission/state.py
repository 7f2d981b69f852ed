"""The mission's state: one dataclass of arrays, each declared once with its shape and reset.

Every array has the leading batch axes of the mission (`()` for one env, `(B,)` for B): per
environment `(*batch,)`, per AUV `(*batch, N)`, and so on. State is updated in place, so that
`reset_rows(mask)` restarts some environments of a batch and leaves the others alone.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from iout_mj.types import BoolArray, FloatArray, IntArray

SHAPES = {
    "env": lambda n, k: (),
    "env_xy": lambda n, k: (2,),
    "auv": lambda n, k: (n,),
    "auv_xy": lambda n, k: (n, 2),
    "auv_action": lambda n, k: (n, 4),
    "auv_node": lambda n, k: (n, k),
}


def _array(axes: str, fill: Any = 0.0, dtype: type = float) -> Any:
    """A state array: its axes (a key of SHAPES), its value after a reset (None: set by the
    mission from the episode's draws) and its dtype."""
    return field(default=None, metadata={"axes": axes, "fill": fill, "dtype": dtype})


@dataclass
class MissionState:
    """Everything that changes during an episode, except the nodes (`SensorNetwork`)."""

    # Vehicles, per AUV.
    positions_m: FloatArray = _array("auv_xy", None)
    headings_rad: FloatArray = _array("auv", None)
    """Measured headings, wrapped to (-pi, pi]."""
    speeds_mps: FloatArray = _array("auv", None)
    """Measured speeds over ground."""
    heading_sp: FloatArray = _array("auv", None)
    """Heading setpoints (unwrapped: a turn across +-pi stays continuous)."""
    speed_sp: FloatArray = _array("auv", None)
    straight_end_m: FloatArray = _array("auv_xy", None)
    """Where each AUV would end the slot flying straight with its new setpoints."""
    boundary_attempt: BoolArray = _array("auv", False, bool)
    """The straight move of this slot would leave the area."""
    action: IntArray = _array("auv_action", 0, np.int64)
    """The decoded action of the last slot: (heading, speed, aet_node, uplink_node) indices."""
    docked: BoolArray = _array("auv", False, bool)
    dock_dist_m: FloatArray = _array("auv", None)
    deadline_slack_m: FloatArray = _array("auv", None)
    """How much farther from the dock than reachable at v_ref in the time left (>= 0)."""
    distance_m: FloatArray = _array("auv_node", None)
    """AUV-node distances at the end of the last slot (at the start after a reset)."""
    battery_j: FloatArray = _array("auv", None)
    propulsion_energy_j: FloatArray = _array("auv")
    """Electrical propulsion energy so far, hotel load included."""
    yaw_energy_j: FloatArray = _array("auv")
    # Per environment.
    current_mps: FloatArray = _array("env_xy", None)
    slot: IntArray = _array("env", 0, np.int64)
    sum_mean_aoi: FloatArray = _array("env")
    sum_objective: FloatArray = _array("env")
    aoi_after_mission: FloatArray = _array("env")
    """Mean-AoI sum of the slots left after an early end (booked when the episode ends)."""
    min_separation_m: FloatArray = _array("env", np.inf)
    collisions: IntArray = _array("env", 0, np.int64)
    all_docked_paid: BoolArray = _array("env", False, bool)
    reward: FloatArray = _array("env", None)
    """The last slot's reward (kept for finished rows of a batch across a partial reset)."""
    terminated: BoolArray = _array("env", False, bool)
    """All docked, or a battery is empty."""
    truncated: BoolArray = _array("env", False, bool)
    """T_max reached without termination."""

    @classmethod
    def zeros(cls, batch: tuple[int, ...], n_auvs: int, n_nodes: int) -> MissionState:
        """Every array allocated (zeros, or its reset value) for `batch` environments."""
        arrays = {}
        for f in dataclasses.fields(cls):
            meta = f.metadata
            shape = (*batch, *SHAPES[meta["axes"]](n_auvs, n_nodes))
            fill = 0 if meta["fill"] is None else meta["fill"]
            arrays[f.name] = np.full(shape, fill, dtype=meta["dtype"])
        return cls(**arrays)

    def reset_rows(self, rows: Any) -> None:
        """Reset every array with a fixed reset value in the given batch rows."""
        for f in dataclasses.fields(self):
            if f.metadata["fill"] is not None:
                getattr(self, f.name)[rows] = f.metadata["fill"]
