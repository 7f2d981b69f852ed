"""The paper's discrete-time kinematics and cubic energy model: the fast backend (no MuJoCo).

Same spaces, mission rules, reward and metrics as the MuJoCo task (`iout_mj.mission.Mission`);
the vehicles jump to p + v_sp * slot * (cos theta_sp, sin theta_sp) + current * slot each
slot, a move that would end outside the area is rejected (the AUV stays), and propulsion
energy is `propulsion.travel_energy_j` (the hotel load is booked by the mission).
`move` works on one environment or on a batch; `KinematicEnvironment` is the dm_env of one,
`iout_mj.envs.KinematicVecEnv` steps B of them per call.
"""

from __future__ import annotations

from typing import Any

import dm_env
import numpy as np
from dm_env import specs

from iout_mj.config import Config
from iout_mj.mission import Mission
from iout_mj.world import propulsion
from iout_mj.world.geometry import norm_xy, wrap_angle

PATH_FRACTIONS = np.linspace(0.0, 1.0, 6)[1:]
"""Points along each straight slot move (fractions of it) at which separations are checked."""


def move(m: Mission, action: Any) -> Any:
    """One slot of the kinematic model for every environment of `m`; returns the reward.

    Each AUV flies its setpoints through the water and drifts with the ocean current (as the
    physics does); a move that would end outside the area is rejected (the AUV stays).
    Propulsion energy is the paper's, for the distance flown through the water."""
    s = m.state
    start = s.positions_m.copy()
    heading, speed = m.begin_slot(action)
    drift = np.where(s.docked[..., None], 0.0, s.current_mps[..., None, :] * m.cfg.scenario.slot_s)
    end = s.straight_end_m + drift
    rejected = s.boundary_attempt | ((end < 0) | (end > m.area_m)).any(axis=-1)
    end = np.where(rejected[..., None], start, end)
    through_water_m = np.where(rejected, 0.0, norm_xy(s.straight_end_m - start))
    prop = propulsion.travel_energy_j(speed, through_water_m, m.cfg.motion)
    fraction = PATH_FRACTIONS.reshape(-1, *[1] * end.ndim)
    return m.end_slot(
        end,
        wrap_angle(heading),
        speed,
        prop,
        np.zeros_like(prop),
        start + fraction * (end - start),
    )


class KinematicEnvironment(dm_env.Environment):
    """dm_env interface over `Mission` with kinematic motion."""

    def __init__(self, cfg: Config, seed: int | None = None, random_layout: bool = False):
        self.cfg = cfg
        self.mission = Mission(cfg, random_layout_per_episode=random_layout)
        self.random = np.random.RandomState(seed)
        self._reset_next = True

    def reseed(self, seed: int | None) -> None:
        self.random = np.random.RandomState(seed)

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
