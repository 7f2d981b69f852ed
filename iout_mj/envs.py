"""gymnasium adapter over both backends; registered as `iout_mj/MultiAUV-v0`."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.utils import EzPickle

from iout_mj.config import Config, ConfigError, make_config
from iout_mj.mission import OBS_HIGH, OBS_LOW, OBSERVATION_DOC, flatten_observation

ENV_ID = "iout_mj/MultiAUV-v0"
BACKENDS = ("mujoco", "kinematic")
LAYOUTS = ("paper", "random")


def resolve_config(
    config: Config | dict[str, Any] | str | Path | None,
    n_auvs: int | None,
    n_nodes: int | None,
    layout: str,
    layout_seed: int = 0,
) -> Config:
    """A Config from a Config, a dict, a YAML/JSON path or None, with N, K and layout applied."""
    if config is None:
        base = Config()
    elif isinstance(config, Config):
        base = config
    elif isinstance(config, dict):
        base = Config.from_dict(config)
    elif isinstance(config, (str, Path)):
        base = Config.load(config)
    else:
        raise ConfigError(f"config={config!r}: accepted a Config, a dict, a file path or None")
    if layout not in LAYOUTS:
        raise ConfigError(f"layout={layout!r} is invalid: accepted one of {LAYOUTS}")
    if n_auvs is None and n_nodes is None and layout == "paper":
        return base
    n = base.scenario.n_auvs if n_auvs is None else n_auvs
    k = base.scenario.n_nodes if n_nodes is None else n_nodes
    return make_config(n, k, layout, seed=layout_seed, base=base)


class MultiAUVEnv(gym.Env[np.ndarray, np.ndarray], EzPickle):
    """N AUVs charge (AET) and collect from K seabed nodes, then dock; one step = one 25 s slot.

    Action: MultiDiscrete([11, 7, K, K] * N); for AUV i the four entries are
      heading index (dtheta = (2 j/10 - 1) * 25 deg), speed index (dv = (2 j/6 - 1) * 0.4 m/s),
      the node it charges by AET, and the node it collects from.

    Reward: the paper's reward as a sum of named terms, each in `info["reward_terms"]`.
    At episode end `info["metrics"]` holds the episode metrics (see README).

    Args:
        n_auvs: AUVs (1 to 4); None takes the config's.
        n_nodes: nodes (2 to 30); None takes the config's.
        backend: "mujoco" (physics) or "kinematic" (the paper's model, fast).
        layout: "paper" (7 or 13 nodes) or "random" (a new seeded layout every episode).
        render_mode: None or "rgb_array".
        config: a Config, dict, YAML/JSON path, or None for the paper's defaults.
        width, height: frame size for "rgb_array".
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 30}  # noqa: RUF012
    __doc__ = (__doc__ or "") + "\n" + OBSERVATION_DOC

    def __init__(
        self,
        n_auvs: int | None = None,
        n_nodes: int | None = None,
        backend: str = "mujoco",
        layout: str = "paper",
        render_mode: str | None = None,
        config: Config | dict[str, Any] | str | Path | None = None,
        width: int = 640,
        height: int = 480,
    ):
        EzPickle.__init__(
            self, n_auvs, n_nodes, backend, layout, render_mode, config, width, height
        )
        if backend not in BACKENDS:
            raise ValueError(f"backend={backend!r} is invalid: accepted one of {BACKENDS}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(
                f"render_mode={render_mode!r} is invalid: accepted None or 'rgb_array'"
            )
        self.cfg = resolve_config(config, n_auvs, n_nodes, layout)
        self.backend = backend
        self.render_mode = render_mode
        self.width, self.height = width, height
        random_layout = layout == "random"
        # Errors that end an episode instead of propagating (none for the kinematic model).
        self._divergence: tuple[type[Exception], ...] = ()
        if backend == "mujoco":
            from dm_control.rl.control import PhysicsError

            from iout_mj.task import make_environment

            self._env: Any = make_environment(self.cfg, random_layout=random_layout)
            self.mission = self._env.task.mission
            self._divergence = (PhysicsError,)
        else:
            from iout_mj.kinematic import KinematicEnvironment

            self._env = KinematicEnvironment(self.cfg, random_layout=random_layout)
            self.mission = self._env.mission
        self.action_space = gym.spaces.MultiDiscrete(self.mission.action_high.copy())
        size = sum(self.mission.observation_sizes().values())
        self.observation_space = gym.spaces.Box(OBS_LOW, OBS_HIGH, shape=(size,), dtype=np.float32)
        self._last_obs = np.zeros(size, dtype=np.float32)
        self._renderer: Any = None

    @property
    def physics(self) -> Any:
        """The AUVPhysics of the MuJoCo backend (None for the kinematic one)."""
        return getattr(self._env, "physics", None)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        if seed is not None:
            target = self._env.task if self.backend == "mujoco" else self._env
            target.reseed(seed)
        ts = self._env.reset()
        self._last_obs = flatten_observation(ts.observation)
        if self._renderer is not None:
            self._renderer.reset()
        return self._last_obs.copy(), {"slot": 0}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        try:
            ts = self._env.step(action)
        except self._divergence as exc:
            info: dict[str, Any] = {
                "error": f"physics diverged: {exc}",
                "metrics": self.mission.metrics(),
                "slot": int(self.mission.slot),
            }
            return self._last_obs.copy(), 0.0, True, False, info
        obs = flatten_observation(ts.observation)
        if not np.all(np.isfinite(obs)):
            info = {
                "error": "non-finite observation (diverged state)",
                "metrics": self.mission.metrics(),
                "slot": int(self.mission.slot),
            }
            return self._last_obs.copy(), 0.0, True, False, info
        self._last_obs = obs
        terminated = bool(ts.last() and ts.discount == 0.0)
        truncated = bool(ts.last() and not terminated)
        terms = {k: float(v) for k, v in self.mission.terms.items()}
        info = {"reward_terms": terms, "slot": int(self.mission.slot)}
        if ts.last():
            info["metrics"] = self.mission.metrics()
        if self._renderer is not None:
            self._renderer.record_slot()
        return obs.copy(), float(ts.reward), terminated, truncated, info

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            return None
        if self._renderer is None:
            from iout_mj.render import MissionRenderer

            self._renderer = MissionRenderer(self, self.width, self.height)
        return self._renderer.frame()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        physics = self.physics
        if physics is not None:
            physics.free()
        super().close()
