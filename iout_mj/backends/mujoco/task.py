"""dm_control Task on AUVPhysics: actions -> servo setpoints, mission bookkeeping per slot.

The three module functions join a `Mission` (one env or a batch) to its AUVPhysics (one per
env); the task uses them with one physics, `iout_mj.envs.PhysicsVecEnv` with B.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from dm_control.rl import control
from dm_control.suite import base
from dm_env import specs

from iout_mj.backends.mujoco.physics import AUVPhysics
from iout_mj.config import Config
from iout_mj.errors import require_seed
from iout_mj.mission import Mission


def start_episode(mission: Mission, physics: AUVPhysics, env: Any = ()) -> None:
    """Put environment `env` of a just reset `mission` (nodes, current, vehicles) into physics."""
    physics.place_scene(mission.network.nodes_m[env], mission.state.current_mps[env])
    physics.set_poses(
        mission.state.positions_m[env],
        mission.state.headings_rad[env],
        mission.state.speeds_mps[env],
    )


def command(mission: Mission, physics: Sequence[AUVPhysics], action: Any) -> None:
    """Apply an action: setpoints to every vehicle's servos, and start the slot's energy
    reading (`book` reads it)."""
    heading_sp, speed_sp = mission.begin_slot(action)
    n = mission.n_auvs
    for p, h, v in zip(physics, heading_sp.reshape(-1, n), speed_sp.reshape(-1, n), strict=True):
        p.set_commands(h, v)
        p.meter.start()


def book(mission: Mission, physics: Sequence[AUVPhysics]) -> Any:
    """Book the slot the vehicles have just flown (measured state and energy since `command`);
    returns the reward (per environment)."""
    b, layout = mission.batch, physics[0]  # every physics of the batch has one layout
    qpos = np.stack([p.data.ptr.qpos for p in physics]).reshape(*b, -1)
    qvel = np.stack([p.data.ptr.qvel for p in physics]).reshape(*b, -1)
    path = np.stack([p.substep_qpos for p in physics], axis=1)
    energy_j = np.stack([p.meter.read_j() for p in physics]).reshape(*b, -1, 2)
    return mission.end_slot(
        layout.positions_m(qpos),
        layout.headings_rad(qpos),
        layout.speeds_mps(qvel),
        energy_j[..., 0],
        energy_j[..., 1],
        layout.positions_m(path.reshape(len(path), *b, -1)),
    )


class DataCollectionTask(base.Task):
    """Multi-AUV AET + data collection; one control step is one slot."""

    def __init__(self, cfg: Config, random: Any = None, random_layout: bool = False):
        super().__init__(random=random)
        self.cfg = cfg
        self.mission = Mission(cfg, random_layout_per_episode=random_layout)

    def reseed(self, seed: int | None) -> None:
        """The task RNG restarted from `seed` (an integer from 0 to 2^32 - 1, or None)."""
        self._random = np.random.RandomState(require_seed(seed, allow_none=True))

    def initialize_episode(self, physics: AUVPhysics) -> None:
        self.mission.reset(self.random)
        start_episode(self.mission, physics)

    def action_spec(self, physics: AUVPhysics) -> specs.BoundedArray:
        return self.mission.actions.spec()

    def before_step(self, action: Any, physics: AUVPhysics) -> None:
        command(self.mission, [physics], action)

    def after_step(self, physics: AUVPhysics) -> None:
        book(self.mission, [physics])

    def get_observation(self, physics: AUVPhysics) -> dict[str, np.ndarray]:
        return self.mission.observation()

    def get_reward(self, physics: AUVPhysics) -> float:
        return float(self.mission.state.reward)

    def get_termination(self, physics: AUVPhysics) -> float | None:
        if self.mission.state.terminated:
            return 0.0
        if self.mission.state.truncated:
            return 1.0
        return None


def substeps_per_slot(cfg: Config, dt_s: float) -> int:
    """Physics substeps in one slot; the slot must be a whole number of timesteps."""
    n_sub = round(cfg.scenario.slot_s / dt_s)
    if abs(n_sub * dt_s - cfg.scenario.slot_s) > 1e-9 * cfg.scenario.slot_s:
        raise ValueError(
            f"slot_s={cfg.scenario.slot_s} is not a multiple of physics timestep_s={dt_s}"
        )
    return n_sub


def make_environment(
    cfg: Config, seed: int | None = None, random_layout: bool = False
) -> control.Environment:
    """The dm_control environment: AUVPhysics + DataCollectionTask, one slot per step."""
    require_seed(seed, allow_none=True)
    physics = AUVPhysics.from_config(cfg)
    task = DataCollectionTask(cfg, random=seed, random_layout=random_layout)
    n_sub = substeps_per_slot(cfg, physics.dt_s)
    return control.Environment(physics, task, n_sub_steps=n_sub, legacy_step=False)
