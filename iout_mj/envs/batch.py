"""B environments of either backend stepped together: the one batched core that the SB3 VecEnvs
and the gymnasium VectorEnv adapt (no stable-baselines3, no gymnasium here).

- kinematic: the paper's kinematics on the whole batch (`backends.kinematic.move`), one core;
- mujoco: B MuJoCo scenes stepped by one `mujoco.rollout` call, whose C threads (`nthread`)
  share the slot's substeps between cores: no worker processes, no pickling.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from iout_mj.backends.kinematic import move
from iout_mj.backends.mujoco.physics import AUVPhysics, Stepper
from iout_mj.backends.mujoco.task import book, command, start_episode, substeps_per_slot
from iout_mj.backends.mujoco.warp_stepper import WarpStepper
from iout_mj.mission import Mission
from iout_mj.mission.tokens import observe_tokens
from iout_mj.scenarios import ConfigLike, NodesLike, resolve
from iout_mj.types import BoolArray, FloatArray

OBSERVATIONS = ("flat", "tokens")
DIVERGED = "physics diverged (MuJoCo reset the state)"


@dataclass
class BatchStep:
    """One step of the batch, environments that ended already restarted."""

    obs: np.ndarray
    """(B, D) observations; the first of a new episode where one ended."""
    rewards: FloatArray
    """(B,) rewards, 0 where the physics diverged."""
    terminated: BoolArray
    """(B,) all docked, a battery empty, or the physics diverged."""
    truncated: BoolArray
    """(B,) T_max reached."""
    ended: dict[int, tuple[np.ndarray, dict[str, Any]]] = field(default_factory=dict)
    """Env index -> (its last observation, {"metrics": ..., and "error" if it diverged})."""


class MissionBatch:
    """A batched Mission and the vehicles it moves.

    Args:
        n_envs: B, the number of environments.
        backend: "kinematic", "mujoco" (C MuJoCo) or "warp" (MuJoCo Warp on a GPU, else on
            Warp's CPU device; the same scenes, see `backends.mujoco.warp_stepper`).
        n_auvs, n_nodes, layout, config: as for `gymnasium.make("iout_mj/MultiAUV-v0", ...)`.
        seed: seeds the one RNG of the batch.
        nthread: C threads of the MuJoCo rollout (0: the calling thread).
        observation: "flat" (the env's) or "tokens" (`mission.tokens`, padded to K_MAX nodes).
    """

    def __init__(
        self,
        n_envs: int,
        backend: str = "kinematic",
        n_auvs: int | None = None,
        n_nodes: int | None = None,
        layout: str | None = None,
        config: ConfigLike = None,
        seed: int | None = None,
        nthread: int = 0,
        observation: str = "flat",
        nodes: NodesLike = None,
    ):
        if observation not in OBSERVATIONS:
            raise ValueError(
                f"observation={observation!r} is invalid: accepted one of {OBSERVATIONS}"
            )
        if not isinstance(n_envs, (int, np.integer)) or n_envs < 1:
            raise ValueError(f"n_envs={n_envs!r} is invalid: accepted an integer >= 1")
        if not isinstance(nthread, (int, np.integer)) or nthread < 0:
            raise ValueError(f"nthread={nthread!r} is invalid: accepted an integer >= 0")
        self.n_envs, self.backend = int(n_envs), backend
        self.env_spec = resolve(config, n_auvs, n_nodes, layout, backend, nodes)
        self.cfg = self.env_spec.config
        self.mission = Mission(self.cfg, self.env_spec.random_per_episode, n_envs=self.n_envs)
        self.random = np.random.RandomState(seed)
        self.physics: list[AUVPhysics] = []
        self.stepper: Stepper | WarpStepper | None = None
        if backend in ("mujoco", "warp"):
            self.physics = [AUVPhysics.from_config(self.cfg) for _ in range(self.n_envs)]
            self.substeps = substeps_per_slot(self.cfg, self.physics[0].dt_s)
            self.stepper = WarpStepper() if backend == "warp" else Stepper(nthread)
        self._none_failed = np.zeros(self.n_envs, dtype=bool)
        self.observation = observation

    def observe(self) -> np.ndarray:
        """(B, D) observations of the current state."""
        if self.observation == "tokens":
            return observe_tokens(self.mission)
        return self.mission.flat_observation()

    def restart(self, mask: BoolArray | None = None) -> None:
        """Start new episodes where `mask` (everywhere for None), drawing from the batch RNG."""
        self.mission.reset(self.random, mask)
        rows = range(self.n_envs) if mask is None else np.flatnonzero(mask)
        for e in rows if self.physics else ():
            start_episode(self.mission, self.physics[e], int(e))

    def move(self, actions: Any) -> tuple[FloatArray, BoolArray]:
        """One slot for every environment: rewards, and which envs failed (physics diverged)."""
        if self.stepper is None:
            return move(self.mission, actions), self._none_failed
        command(self.mission, self.physics, actions)
        failed = self.stepper.step(self.physics, self.substeps)
        return book(self.mission, self.physics), failed

    def step(self, actions: Any) -> BatchStep:
        """Move every environment one slot, then restart those that ended (autoreset)."""
        m = self.mission
        rewards, failed = self.move(actions)
        obs = self.observe()
        terminated = m.state.terminated | failed
        truncated = m.state.truncated & ~failed
        done = terminated | truncated
        ended: dict[int, tuple[np.ndarray, dict[str, Any]]] = {}
        if done.any():
            for e in np.flatnonzero(done):
                info: dict[str, Any] = {"metrics": m.metrics(int(e))}
                if failed[e]:
                    info["error"] = DIVERGED
                ended[int(e)] = (obs[e].copy(), info)
            self.restart(done)
            obs[done] = self.observe()[done]
        return BatchStep(obs, np.where(failed, 0.0, rewards), terminated, truncated, ended)

    def close(self) -> None:
        if self.stepper is not None:
            self.stepper.close()
            self.stepper = None
        for p in self.physics:
            p.free()
        self.physics = []
