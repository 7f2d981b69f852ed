"""The mission's state: one dataclass of arrays, each declared once with its shape and reset.

Every array has the leading batch axes of the mission (`()` for one env, `(B,)` for B): per
environment `(*batch,)`, per AUV `(*batch, N)`, and so on. State is updated in place, so that
`reset_rows(mask)` restarts some environments of a batch and leaves the others alone, and so
that `arrays()`, the same memory with a batch axis always (one env: of one), is what the
compiled rules (`mission.rules`) write. The compiled rules point into these arrays, so they
cannot be rebound (`native.Frozen`), only written in place; `native.h` declares the same
fields (IOUT_STATE, IOUT_LOG), checked at import by name and element type.
"""

from __future__ import annotations

import dataclasses
from collections import namedtuple
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from iout_mj import native
from iout_mj.types import BoolArray, FloatArray, IntArray

SHAPES = {
    "env": lambda n, k, t: (),
    "env_xy": lambda n, k, t: (2,),
    "auv": lambda n, k, t: (n,),
    "auv_xy": lambda n, k, t: (n, 2),
    "auv_action": lambda n, k, t: (n, 4),
    "auv_node": lambda n, k, t: (n, k),
    "states": lambda n, k, t: (t + 1,),
    "states_auv": lambda n, k, t: (t + 1, n),
    "states_auv_xy": lambda n, k, t: (t + 1, n, 2),
    "slots_auv": lambda n, k, t: (t, n),
}
"""Axes of the arrays, for N AUVs, K nodes and T_max slots (the log keeps T_max + 1 states: the
start and the end of every slot)."""


def _array(axes: str, fill: Any = 0.0, dtype: type = float) -> Any:
    """A state array: its axes (a key of SHAPES), its value after a reset (None: set by the
    mission from the episode's draws) and its dtype."""
    return field(default=None, metadata={"axes": axes, "fill": fill, "dtype": dtype})


@dataclass
class MissionState(native.Frozen):
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
        state = cls(**_allocate(cls, batch, n_auvs, n_nodes, 0))
        state._freeze()
        return state

    def reset_rows(self, rows: Any) -> None:
        """Reset every array with a fixed reset value in the given batch rows."""
        for f in dataclasses.fields(self):
            if f.metadata["fill"] is not None:
                getattr(self, f.name)[rows] = f.metadata["fill"]

    def arrays(self, batched: bool) -> Any:
        """The same arrays with a leading batch axis (a `MissionArrays` of views)."""
        return _with_batch_axis(self, MissionArrays, batched)


@dataclass
class MissionLog(native.Frozen):
    """Per-slot history of the episode (for metrics, figures and rendering): entry t of the
    states is the state after slot t (0: the start), entry t of the links is slot t + 1's."""

    positions_m: FloatArray = _array("states_auv_xy")
    headings_rad: FloatArray = _array("states_auv")
    speeds_mps: FloatArray = _array("states_auv")
    mean_aoi: FloatArray = _array("states")
    jain: FloatArray = _array("states")
    aet_nodes: IntArray = _array("slots_auv", 0, np.int64)
    uplink_nodes: IntArray = _array("slots_auv", 0, np.int64)
    uplink_ok: BoolArray = _array("slots_auv", False, bool)

    @classmethod
    def zeros(cls, batch: tuple[int, ...], n_auvs: int, horizon_slots: int) -> MissionLog:
        log = cls(**_allocate(cls, batch, n_auvs, 0, horizon_slots))
        log._freeze()
        return log

    def arrays(self, batched: bool) -> Any:
        """The same arrays with a leading batch axis (a `LogArrays` of views)."""
        return _with_batch_axis(self, LogArrays, batched)


def _allocate(cls: Any, batch: tuple[int, ...], n: int, k: int, t: int) -> dict[str, Any]:
    arrays = {}
    for f in dataclasses.fields(cls):
        meta = f.metadata
        shape = (*batch, *SHAPES[meta["axes"]](n, k, t))
        fill = 0 if meta["fill"] is None else meta["fill"]
        arrays[f.name] = native.allocate(shape, meta["dtype"], fill)
    return arrays


def _with_batch_axis(obj: Any, kind: Any, batched: bool) -> Any:
    """`kind` (a namedtuple of the fields) of views with a batch axis: one env gains one."""
    one = () if batched else (None,)
    return kind(*(getattr(obj, f)[one] for f in kind._fields))


MissionArrays = namedtuple(  # type: ignore[misc]
    "MissionArrays", [f.name for f in dataclasses.fields(MissionState)]
)
LogArrays = namedtuple("LogArrays", [f.name for f in dataclasses.fields(MissionLog)])  # type: ignore[misc]
for _cls, _owner in ((MissionState, "State"), (MissionLog, "Log")):
    native.require_fields(
        _owner, {f.name: np.dtype(f.metadata["dtype"]) for f in dataclasses.fields(_cls)}
    )
