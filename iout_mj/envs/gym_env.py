"""The gymnasium env over either backend; registered as `iout_mj/MultiAUV-v0`."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from dm_control.rl.control import PhysicsError
from gymnasium.utils import EzPickle

from iout_mj.backends.kinematic import KinematicEnvironment, move
from iout_mj.backends.mujoco import vehicle
from iout_mj.backends.mujoco.render import MissionRenderer
from iout_mj.backends.mujoco.task import make_environment
from iout_mj.backends.registry import SINGLE_ENV_BACKENDS
from iout_mj.errors import require_seed
from iout_mj.mission import OBS_HIGH, OBS_LOW, OBSERVATION_DOC, REWARD_TERMS, Mission
from iout_mj.mission.observation import flatten_observation
from iout_mj.scenarios import ConfigLike, NodesLike, resolve

ENV_ID = "iout_mj/MultiAUV-v0"
BACKENDS = SINGLE_ENV_BACKENDS
RENDER_MODES = ("rgb_array", "rgb_array_list")


def spaces(mission: Mission) -> tuple[gym.spaces.Box, gym.spaces.MultiDiscrete]:
    """Observation and action space of one environment of `mission`."""
    size = sum(mission.observation_sizes.values())
    observation = gym.spaces.Box(OBS_LOW, OBS_HIGH, shape=(size,), dtype=np.float32)
    return observation, gym.spaces.MultiDiscrete(mission.actions.high.copy())


class MultiAUVEnv(gym.Env[np.ndarray, np.ndarray], EzPickle):
    """N AUVs charge (AET) and collect from K seabed nodes, then dock; one step = one 25 s slot.

    ## Action Space
    `MultiDiscrete([11, 7, K, K] * N)`; for AUV i the four entries are the heading index
    (dtheta = (2 j/10 - 1) * 25 deg), the speed index (dv = (2 j/6 - 1) * 0.4 m/s), the node it
    charges by AET and the node it collects from. A bad action raises `ValueError` naming the
    AUV, the field and the accepted range.

    ## Observation Space
    `Box(-1, 2, (D,), float32)`, the groups below in order (`iout_mj.mission.observation`).

    ## Rewards
    The sum of the terms of `iout_mj.mission.rewards` (AoI, fairness, docking, collision,
    boundary, stall, energy margin, infeasible uplink, deadline shaping, docking progress,
    undocked at the end, AoI after an early end), each signed weight in
    `config.reward.weights`; `info["reward_terms"]` holds every term of the step.

    ## Starting State
    AUV i starts at `scenario.starts_m[i]` plus a uniform jitter of up to 10 m per axis,
    heading 0 +- 5 deg, speed 1 m/s; nodes hold 0.1 J and AoI 1. With `layout="random"` every
    episode draws a new node layout, and `physics.current_jitter_mps` a random current, from
    the task RNG (`reset(seed=...)`).

    ## Episode End
    Terminated when every AUV is docked or a battery is empty; truncated after T_max = 55
    slots; terminated with `info["error"]` if the physics diverged. `info["metrics"]` holds
    the episode metrics at the end.

    ## Arguments
    n_auvs: AUVs (1 to 4); None takes the config's.
    n_nodes: nodes (2 to 30); None takes the config's.
    backend: "mujoco" (physics) or "kinematic" (the paper's model, fast).
    layout: "paper" (the paper's nodes for K = 7 and 13, one seeded layout per K otherwise)
        or "random" (a new seeded layout every episode); None: the config's own nodes if it
        sets them (kept in every episode), else "paper" (`iout_mj.scenarios.resolve`).
    render_mode: None, "rgb_array" (the current frame) or "rgb_array_list" (every frame since
        the last `render()`: 8 per slot, from the physics substeps).
    config: a Config, dict, YAML/JSON path, or None for the paper's defaults.
    width, height: frame size in pixels.
    nodes: the nodes, as a list of (x, y) in metres or a CSV file, instead of the config's.

    ## Version History
    v0: the paper's system on MuJoCo physics with measured propulsion energy.

    (Over the house's ~150 lines of a class: a third of it is this Gymnasium-style docstring.)
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 30}  # noqa: RUF012
    __doc__ = (__doc__ or "") + "\n" + OBSERVATION_DOC
    reward_terms = REWARD_TERMS

    def __init__(
        self,
        n_auvs: int | None = None,
        n_nodes: int | None = None,
        backend: str = "mujoco",
        layout: str | None = None,
        render_mode: str | None = None,
        config: ConfigLike = None,
        width: int = 640,
        height: int = 480,
        nodes: NodesLike = None,
    ):
        EzPickle.__init__(
            self, n_auvs, n_nodes, backend, layout, render_mode, config, width, height, nodes
        )
        if backend not in BACKENDS:
            raise ValueError(
                f"backend={backend!r} is invalid for one env: accepted one of {BACKENDS} "
                "(warp steps batches: iout_mj.envs.WarpVecEnv)"
            )
        if render_mode not in (None, *RENDER_MODES):
            raise ValueError(
                f"render_mode={render_mode!r} is invalid: accepted None or one of {RENDER_MODES}"
            )
        self.env_spec = resolve(config, n_auvs, n_nodes, layout, backend, nodes)
        self.cfg = self.env_spec.config
        self.backend = backend
        self.render_mode = render_mode
        self.width, self.height = width, height
        random_layout = self.env_spec.random_per_episode
        self._env: Any
        if backend == "mujoco":
            self._env = make_environment(self.cfg, random_layout=random_layout)
            self.mission = self._env.task.mission
        else:
            self._env = KinematicEnvironment(self.cfg, random_layout=random_layout)
            self.mission = self._env.mission
        self.observation_space, self.action_space = spaces(self.mission)
        self._last_obs = np.zeros(self.observation_space.shape, dtype=np.float32)
        self._renderer: MissionRenderer | None = None
        self._needs_reset = True

    @property
    def physics(self) -> Any:
        """The AUVPhysics of the MuJoCo backend (None for the kinematic one)."""
        return getattr(self._env, "physics", None)

    @property
    def renderer(self) -> MissionRenderer:
        """The offscreen renderer of this env (built on first use)."""
        if self._renderer is None:
            physics = self.physics
            model = vehicle.build_model(self.cfg) if physics is None else physics.model.ptr
            self._renderer = MissionRenderer(
                model, self.mission, self.width, self.height, physics=physics
            )
        return self._renderer

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        seed = require_seed(seed, allow_none=True)
        super().reset(seed=seed)
        if seed is not None:
            target = self._env.task if self.backend == "mujoco" else self._env
            target.reseed(seed)
        ts = self._env.reset()
        self._needs_reset = False
        self._last_obs = flatten_observation(ts.observation)
        if self.render_mode is not None:
            self.renderer.reset()
            if self.render_mode == "rgb_array_list":
                self.renderer.record_frame()
        return self._last_obs.copy(), {"slot": 0}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self._needs_reset:
            raise RuntimeError(
                "step() before reset() or after the episode ended: call reset() first"
            )
        mission = self.mission
        if self.backend == "kinematic":  # the lean path: one compiled call, no dm_env
            reward = float(move(mission, action))
            obs = mission.flat_observation()
        else:
            try:
                ts = self._env.step(action)
            except PhysicsError as exc:
                return self._failed(str(exc))
            reward = float(ts.reward)
            obs = flatten_observation(ts.observation)  # the task's, not observed a second time
            if not np.all(np.isfinite(obs)):
                return self._failed("non-finite observation (diverged state)")
        self._last_obs = obs
        terminated, truncated = bool(mission.state.terminated), bool(mission.state.truncated)
        self._needs_reset = terminated or truncated
        info = {"reward_terms": mission.terms, "slot": int(mission.state.slot)}
        channel = mission.channel_info()
        if channel is not None:  # the channel's per-AUV uplinks (sinr_db, per, packets)
            info["channel"] = channel
        if self._needs_reset:
            info["metrics"] = mission.metrics()
        if self.render_mode == "rgb_array_list":
            self.renderer.record_slot()
        elif self._renderer is not None:  # rgb_array: trails only, nobody takes slot frames
            self._renderer.record_slot(keep_frames=False)
        return obs.copy(), reward, terminated, truncated, info

    def _failed(self, error: str) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """The step of a diverged physics: the episode ends, the error is reported."""
        self._needs_reset = True
        info = {
            "error": error,
            "metrics": self.mission.metrics(),
            "slot": int(self.mission.state.slot),
        }
        return self._last_obs.copy(), 0.0, True, False, info

    def render(self) -> Any:
        if self.render_mode is None:
            return None
        if self.render_mode == "rgb_array_list":
            return self.renderer.take_frames()
        return self.renderer.frame()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        physics = self.physics
        if physics is not None:
            physics.free()
        super().close()
