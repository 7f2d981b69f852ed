"""A docking shield: any policy P as `P+dock`, with each AUV's heading and speed taken over by
`tour-scheduler`'s docking approach from the slot at which it must head into the dock to arrive
before the horizon (its final approach at the ground speeds the current allows, with
`TourScheduler.dock_spare_slots` to spare; facing away from the dock, a slow turn first, at
any distance). P still picks every AET and uplink node.

The rule reads an AUV's own position, heading and speed setpoints, the current it drifts in
and the clock, so a shielded decentralised policy stays decentralised. Once an AUV heads home
it stays on the approach until it docks. This is shielding in the sense of Alshiekh et al.,
"Safe Reinforcement Learning via Shielding" (AAAI 2018): a hard constraint of the task (dock
before T_max) kept by a monitor that overrides only the actions that would break it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from iout_mj.agents.planners import TourScheduler
from iout_mj.agents.rollout import EnvPolicy
from iout_mj.types import BoolArray

DOCK_SUFFIX = "+dock"
"""`<policy>+dock`: the policy with the docking shield."""


class DockShield:
    """`policy(env, obs) -> action` (`rollout.EnvPolicy`): `base` with the docking shield."""

    def __init__(self, base: EnvPolicy) -> None:
        self.base = base
        self.planner = TourScheduler()
        self.planner.slow_turn_within_m = np.inf  # a policy may face away from a far dock
        self._homing: BoolArray | None = None

    def reset(self, seed: int | None) -> None:
        self._homing = None
        reset = getattr(self.base, "reset", None)
        if reset is not None:
            reset(seed)

    def __call__(self, env: Any, obs: np.ndarray) -> np.ndarray:
        mission = env.unwrapped.mission
        action = np.array(self.base(env, obs), dtype=np.int64).reshape(mission.n_auvs, -1)
        if self._homing is None or mission.state.slot == 0:
            self._homing = np.zeros(mission.n_auvs, dtype=bool)
        self._homing |= self.planner.must_dock(mission)
        heading, speed = self.planner.dock_approach(mission)
        action[self._homing, 0] = heading[self._homing]
        action[self._homing, 1] = speed[self._homing]
        return action.ravel()
