"""dm_control Task on AUVPhysics: actions -> servo setpoints, mission bookkeeping per slot."""

from __future__ import annotations

from typing import Any

import numpy as np
from dm_control.rl import control
from dm_control.suite import base
from dm_env import specs

from iout_mj import names
from iout_mj.config import Config
from iout_mj.mission import Mission
from iout_mj.physics import AUVPhysics


class DataCollectionTask(base.Task):
    """Multi-AUV AET + data collection; one control step is one slot."""

    def __init__(self, cfg: Config, random: Any = None, random_layout: bool = False):
        super().__init__(random=random)
        self.cfg = cfg
        self.mission = Mission(cfg, random_layout_per_episode=random_layout)

    def reseed(self, seed: int | None) -> None:
        self._random = np.random.RandomState(seed)

    def initialize_episode(self, physics: AUVPhysics) -> None:
        start, heading, speed = self.mission.reset(self.random)
        m = physics.model.ptr
        for k, (x, y) in enumerate(self.mission.network.nodes_m):
            m.body_pos[m.body(names.node_name(k)).id, :2] = (x, y)
        m.opt.wind[:2] = self.mission.current_mps
        physics.set_poses(start, heading, speed)

    def action_spec(self, physics: AUVPhysics) -> specs.BoundedArray:
        return self.mission.action_spec()

    def before_step(self, action: Any, physics: AUVPhysics) -> None:
        heading_sp, speed_sp = self.mission.begin_slot(action)
        physics.set_commands(heading_sp, speed_sp)
        self._energy_before = physics.mech_energy_j.copy()

    def after_step(self, physics: AUVPhysics) -> None:
        mech = (physics.mech_energy_j - self._energy_before) / self.cfg.motion.prop_efficiency
        self.mission.end_slot(
            physics.positions_m(),
            physics.headings_rad(),
            physics.speeds_mps(),
            mech[:, 0],
            mech[:, 1],
            physics.substep_positions_m(),
        )

    def get_observation(self, physics: AUVPhysics) -> dict[str, np.ndarray]:
        return self.mission.observation()

    def get_reward(self, physics: AUVPhysics) -> float:
        return float(self.mission.reward)

    def get_termination(self, physics: AUVPhysics) -> float | None:
        if self.mission.terminated:
            return 0.0
        if self.mission.truncated:
            return 1.0
        return None


def make_environment(
    cfg: Config, seed: int | None = None, random_layout: bool = False
) -> control.Environment:
    """The dm_control environment: AUVPhysics + DataCollectionTask, one slot per step."""
    physics = AUVPhysics.from_config(cfg)
    task = DataCollectionTask(cfg, random=seed, random_layout=random_layout)
    n_sub = round(cfg.scenario.slot_s / physics.dt_s)
    if abs(n_sub * physics.dt_s - cfg.scenario.slot_s) > 1e-9 * cfg.scenario.slot_s:
        raise ValueError(
            f"slot_s={cfg.scenario.slot_s} is not a multiple of physics timestep_s={physics.dt_s}"
        )
    return control.Environment(physics, task, n_sub_steps=n_sub, legacy_step=False)
