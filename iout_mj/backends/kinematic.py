"""The paper's discrete-time kinematics and cubic energy model: the fast backend (no MuJoCo).

Same spaces, mission rules, reward and metrics as the MuJoCo task (`iout_mj.mission.Mission`);
the vehicles jump to p + v_sp * slot * (cos theta_sp, sin theta_sp) + current * slot each
slot, a move that would end outside the area is rejected (the AUV stays), and propulsion
energy is the cubic drag term for the distance flown through the water (the hotel load is
booked by the mission). `move` runs the whole slot, the mission's rules included, as one
compiled call (`kinematic.c`), for one environment or a batch; `KinematicEnvironment` is the
dm_env of one, `iout_mj.envs.KinematicVecEnv` steps B of them per call. Separations are
checked at 5 points along each straight move.
"""

from __future__ import annotations

from typing import Any

import dm_env
import numpy as np
from dm_env import specs

from iout_mj import native
from iout_mj.config import Config
from iout_mj.errors import require_seed
from iout_mj.mission import Mission


def move(m: Mission, action: Any) -> Any:
    """One slot of the kinematic model for every environment of `m`; returns the reward.

    Each AUV flies its setpoints through the water and drifts with the ocean current (as the
    physics does); a move that would end outside the area is rejected (the AUV stays).
    Propulsion energy is the paper's, for the distance flown through the water."""
    m.set_actions(action)
    native.call(native.lib.iout_kinematic_slot, m._view_address)
    return m.state.reward[()]


class KinematicEnvironment(dm_env.Environment):
    """dm_env interface over `Mission` with kinematic motion."""

    def __init__(self, cfg: Config, seed: int | None = None, random_layout: bool = False):
        self.cfg = cfg
        self.mission = Mission(cfg, random_layout_per_episode=random_layout)
        self.random = np.random.RandomState(require_seed(seed, allow_none=True))
        self._reset_next = True

    def reseed(self, seed: int | None) -> None:
        """The task RNG restarted from `seed` (an integer from 0 to 2^32 - 1, or None)."""
        self.random = np.random.RandomState(require_seed(seed, allow_none=True))

    def reset(self) -> dm_env.TimeStep:
        self.mission.reset(self.random)
        self._reset_next = False
        return dm_env.restart(self.mission.observation())

    def step(self, action: Any) -> dm_env.TimeStep:
        if self._reset_next:
            return self.reset()
        m = self.mission
        reward = float(move(m, action))
        obs = m.observation()
        if m.state.terminated:
            self._reset_next = True
            return dm_env.termination(reward, obs)
        if m.state.truncated:
            self._reset_next = True
            return dm_env.truncation(reward, obs)
        return dm_env.transition(reward, obs)

    def action_spec(self) -> specs.BoundedArray:
        return self.mission.actions.spec()

    def observation_spec(self) -> dict[str, specs.Array]:
        return {
            k: specs.Array(shape=(n,), dtype=np.float64, name=k)
            for k, n in self.mission.observation_sizes.items()
        }
