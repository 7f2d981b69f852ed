"""The paper's discrete-time kinematics and cubic energy model: the fast backend (no MuJoCo).

Same spaces, mission rules, reward and metrics as the MuJoCo task (`mission.Mission`); the
vehicles jump to p + v_sp * slot * (cos theta_sp, sin theta_sp) each slot, a move that would
leave the area is rejected (the AUV stays), and propulsion energy is `energy.slot_energy_j`.
"""

from __future__ import annotations

from typing import Any

import dm_env
import numpy as np
from dm_env import specs

from iout_mj import energy
from iout_mj.config import Config
from iout_mj.mission import Mission

_PATH_SAMPLES = np.linspace(0.0, 1.0, 6)[1:, None, None]
"""Points along each straight slot move at which separations are checked."""


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
        start = m.positions_m
        heading, speed = m.begin_slot(action)
        slot_s = self.cfg.scenario.slot_s
        direction = np.stack([np.cos(heading), np.sin(heading)], axis=1)
        end = start + (speed * slot_s)[:, None] * direction
        end[m.boundary_attempt] = start[m.boundary_attempt]
        travelled = np.linalg.norm(end - start, axis=1)
        prop = energy.travel_energy_j(speed, travelled, self.cfg.motion)
        m.end_slot(
            end,
            np.mod(heading + np.pi, 2 * np.pi) - np.pi,
            speed,
            prop,
            np.zeros(m.n_auvs),
            start + _PATH_SAMPLES * (end - start),
        )
        obs = m.observation()
        if m.terminated:
            self._reset_next = True
            return dm_env.termination(m.reward, obs)
        if m.truncated:
            self._reset_next = True
            return dm_env.truncation(m.reward, obs)
        return dm_env.transition(m.reward, obs)

    def action_spec(self) -> specs.BoundedArray:
        return self.mission.action_spec()

    def observation_spec(self) -> dict[str, specs.Array]:
        return {
            k: specs.Array(shape=(n,), dtype=np.float64, name=k)
            for k, n in self.mission.observation_sizes().items()
        }
