"""A docking shield: any policy P as `P+dock`, with each AUV's heading and speed taken over by
`tour-scheduler`'s docking approach from the slot at which it must head into the dock to arrive
before the horizon (its final approach at the ground speeds the current allows, with
`DOCK_SPARE_SLOTS` to spare; facing away from the dock, a slow turn first, at
any distance, then cruise speed until the final stretch). Until it must head home (in a
current: a few slots before) an AUV is kept out of the dock zone, where it would dock for good
under the zone-entry rule: a move that could lead in is replaced by the nearest one that keeps
it out. P still picks every AET and uplink node.

The rule reads an AUV's own position, heading and speed setpoints, the current it drifts in
and the clock, so a shielded decentralised policy stays decentralised. Once an AUV heads home
it stays on the approach until it docks. This is shielding in the sense of Alshiekh et al.,
"Safe Reinforcement Learning via Shielding" (AAAI 2018): a hard constraint of the task (dock
before T_max) kept by a monitor that overrides only the actions that would break it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from iout_mj.agents.baselines import CRUISE_MPS
from iout_mj.agents.planners import TourScheduler
from iout_mj.agents.rollout import EnvPolicy
from iout_mj.types import BoolArray, IntArray
from iout_mj.world.geometry import slot_velocity_mps

DOCK_SPARE_SLOTS = 4.0
"""Slots to spare at the decision to head home (the planner keeps 2: it heads home from near
the nodes' centroid, while a policy may be anywhere, at any speed, facing away)."""
KEEP_OUT_MARGIN_M = 10.0
"""Clearance from the dock zone kept by an AUV not yet heading home."""
KEEP_OUT_RELEASE_SLOTS_PER_MPS = 6.0
"""An AUV this many slots per m/s of current before it must head home may enter the zone (its
approach from the zone's edge, against a strong current, could orbit the zone instead)."""
DOCK_SUFFIX = "+dock"
"""`<policy>+dock`: the policy with the docking shield."""


def split_shield(name: str) -> tuple[str, bool]:
    """(the policy, whether it is shielded) of a policy name: `P+dock` -> (P, True)."""
    base = name.removesuffix(DOCK_SUFFIX)
    return (base, True) if base and base != name else (name, False)


class DockShield:
    """`policy(env, obs) -> action` (`rollout.EnvPolicy`): `base` with the docking shield;
    without a base, `apply` shields the actions an env is given (training under the shield)."""

    def __init__(self, base: EnvPolicy | None = None) -> None:
        self.base = base
        self.planner = TourScheduler()
        self.planner.dock_spare_slots = DOCK_SPARE_SLOTS
        # a policy may head home from anywhere, facing away: turn slowly, then cruise (the
        # docking decision's own model of the approach)
        self.planner.slow_turn_within_m = np.inf
        self.planner.top_approach_mps = CRUISE_MPS
        self.release = TourScheduler()
        self._homing: BoolArray | None = None

    def reset(self, seed: int | None) -> None:
        self._homing = None
        reset = getattr(self.base, "reset", None)
        if reset is not None:
            reset(seed)

    def __call__(self, env: Any, obs: np.ndarray) -> np.ndarray:
        assert self.base is not None, "DockShield() without a base shields with apply()"
        mission = env.unwrapped.mission
        action = np.array(self.base(env, obs), dtype=np.int64).reshape(mission.n_auvs, -1)
        return self.apply(mission, action).ravel()

    def apply(self, mission: Any, action: IntArray) -> IntArray:
        """Shield the (N, 4) joint action `action` in place for this slot of `mission`."""
        if self._homing is None or mission.state.slot == 0:
            self._homing = np.zeros(mission.n_auvs, dtype=bool)
        self._homing |= self.planner.must_dock(mission)
        if self._homing.any():
            heading, speed = self.planner.dock_approach(mission)
            action[self._homing, 0] = heading[self._homing]
            action[self._homing, 1] = speed[self._homing]
        current_mps = float(np.hypot(*mission.state.current_mps))
        self.release.dock_spare_slots = (
            self.planner.dock_spare_slots + KEEP_OUT_RELEASE_SLOTS_PER_MPS * current_mps
        )
        _keep_out(mission, action, ~(self._homing | self.release.must_dock(mission)))
        return action


def _moves(
    mission: Any, positions_m: np.ndarray, heading_rad: np.ndarray, speed_mps: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """End positions (..., H, S, 2), headings and speeds (..., H, S) of one slot from the given
    states (...) for every pair of heading and speed indices, as the kinematic backend moves
    an AUV (`slot_velocity_mps`)."""
    a, slot_s = mission.actions, mission.cfg.scenario.slot_s
    v_max_mps = mission.cfg.motion.v_max_mps
    heading = heading_rad[..., None, None] + a.dtheta_rad[:, None]
    speed = np.clip(speed_mps[..., None, None] + a.dv_mps, 0.0, v_max_mps)
    heading, speed = np.broadcast_arrays(heading, speed)
    velocity = slot_velocity_mps(heading, speed, mission.state.current_mps, v_max_mps)
    ends = positions_m[..., None, None, :] + velocity * slot_s
    return ends, heading, speed


def _keep_out(mission: Any, action: IntArray, outside: BoolArray) -> None:
    """Change in place the heading and speed indices of the AUVs flagged `outside` whose move
    this slot could lead into the dock zone: to the nearest pair of indices after which the
    AUV ends the slot, and can end the next one, farther than `KEEP_OUT_MARGIN_M` from the
    zone (an AUV with no such pair keeps its choice)."""
    s, radius_m = mission.state, mission.cfg.scenario.dock_radius_m + KEEP_OUT_MARGIN_M
    # two slots move an AUV at most this far: farther from the zone, every move is clear
    reach_m = (
        2
        * mission.cfg.scenario.slot_s
        * (mission.cfg.motion.v_max_mps + float(np.hypot(*s.current_mps)))
    )
    distance_m = np.linalg.norm(s.positions_m - mission.dock_m, axis=-1)
    if not np.any(outside & (distance_m <= radius_m + reach_m)):
        return
    ends, heading, speed = _moves(mission, s.positions_m, s.heading_sp, s.speed_sp)
    end_distance_m = np.linalg.norm(ends - mission.dock_m, axis=-1)  # (N, H, S)
    clear = end_distance_m > radius_m
    # the next slot can lead in only from an end within one slot's reach of the zone
    near = clear & (end_distance_m <= radius_m + reach_m / 2)
    then, _, _ = _moves(mission, ends[near], heading[near], speed[near])  # (M, H, S, 2)
    clear[near] = (np.linalg.norm(then - mission.dock_m, axis=-1) > radius_m).any(axis=(-2, -1))
    h_levels, v_levels = np.arange(clear.shape[1]), np.arange(clear.shape[2])
    change = (
        np.abs(h_levels[None, :, None] - action[:, 0, None, None])
        + np.abs(v_levels[None, None, :] - action[:, 1, None, None])
    ).astype(float)
    change[~clear] = np.inf
    rows = np.arange(len(action))
    blocked = outside & ~clear[rows, action[:, 0], action[:, 1]] & clear.any(axis=(1, 2))
    h, v = np.unravel_index(change.reshape(len(action), -1).argmin(axis=1), clear.shape[1:])
    action[blocked, 0] = h[blocked]
    action[blocked, 1] = v[blocked]
