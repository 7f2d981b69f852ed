"""B environments of either backend stepped together: the one batched core that the SB3 VecEnvs
and the gymnasium VectorEnv adapt (no stable-baselines3, no gymnasium here).

- kinematic: the paper's kinematics on the whole batch (`backends.kinematic.move`), one core;
- mujoco: B MuJoCo scenes stepped by one `mujoco.rollout` call, whose C threads (`nthread`)
  share the slot's substeps between cores: no worker processes, no pickling.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from iout_mj.backends.kinematic import move
from iout_mj.backends.mujoco.physics import AUVPhysics, Stepper
from iout_mj.backends.mujoco.task import book, command, start_episode, substeps_per_slot
from iout_mj.backends.mujoco.warp_stepper import WarpStepper
from iout_mj.mission import Mission
from iout_mj.scenarios import ConfigLike, NodesLike, resolve
from iout_mj.types import BoolArray, FloatArray
from iout_mj.world.network import NETWORK_DTYPES

OBSERVATIONS = ("flat", "tokens")
DIVERGED = "physics diverged (MuJoCo reset the state)"
PHYSICS_STATE = mujoco.mjtState.mjSTATE_INTEGRATION
"""What a saved scene holds: time, qpos, qvel, act, controls, applied forces, warmstart."""
MT_KEY_WORDS = 624
"""Words of an MT19937 state (numpy's RandomState)."""


def rng_arrays(rng: np.random.RandomState) -> dict[str, np.ndarray]:
    """A RandomState's state as arrays: the MT19937 key, [position, has_gauss] and the
    cached Gaussian (`set_rng` puts it back)."""
    _, key, pos, has_gauss, cached = rng.get_state()
    return {
        "key": np.array(key, dtype=np.uint32),
        "pos": np.array([pos, has_gauss], dtype=np.int64),
        "gauss": np.array([cached], dtype=float),
    }


def set_rng(rng: np.random.RandomState, arrays: Mapping[str, np.ndarray]) -> None:
    """Put `rng_arrays` back into `rng` (in place); raises ValueError naming what is wrong."""
    key, pos, gauss = (np.asarray(arrays[k]) for k in ("key", "pos", "gauss"))
    if key.shape != (MT_KEY_WORDS,) or pos.shape != (2,) or gauss.shape != (1,):
        raise ValueError(
            f"RNG state of shapes key {key.shape}, pos {pos.shape}, gauss {gauss.shape}; "
            f"accepted ({MT_KEY_WORDS},), (2,) and (1,)"
        )
    if not (0 <= pos[0] <= MT_KEY_WORDS and pos[1] in (0, 1)):
        raise ValueError(f"RNG position {pos.tolist()}: accepted [0..{MT_KEY_WORDS}, 0 or 1]")
    rng.set_state(("MT19937", key.astype(np.uint32), int(pos[0]), int(pos[1]), float(gauss[0])))


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
    channel: dict[str, np.ndarray] | None = None
    """The slot's uplinks through the channel, (B, N) per quantity (`Mission.channel_info`);
    None on the paper's channel."""


def live_arrays(m: Mission) -> dict[str, np.ndarray]:
    """A mission's own arrays that change as it steps (not copies), by name."""
    out = {f"state.{f.name}": getattr(m.state, f.name) for f in dataclasses.fields(m.state)}
    out.update({f"log.{f.name}": getattr(m.log, f.name) for f in dataclasses.fields(m.log)})
    out.update({f"network.{name}": getattr(m.network, name) for name in NETWORK_DTYPES})
    out["terms"] = m.term_values
    return out


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
            return self.mission.observe_tokens()
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
        channel = m.channel_info()  # before a restart: the slot's links, not a new episode's
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
        rewards = np.where(failed, 0.0, rewards)
        return BatchStep(obs, rewards, terminated, truncated, ended, channel)

    def state_arrays(self) -> dict[str, np.ndarray]:
        """Copies of everything that changes as the batch steps, by name: the mission's state,
        log, nodes and last reward terms, the RNG (`random.*`) and, for MuJoCo, every scene's
        physics state and energy meter. `load_state_arrays` puts the batch back exactly where
        it was; the rest (models, slot buffers) follows from the config and this."""
        live = {name: np.array(value) for name, value in self._live_arrays().items()}
        rng = {f"random.{k}": v for k, v in rng_arrays(self.random).items()}
        return {**live, **rng, **self._scene_arrays()}

    def load_state_arrays(self, arrays: Mapping[str, np.ndarray]) -> None:
        """Put back what `state_arrays` gave, on a batch of the same config and size (the
        mission's arrays are written in place: the compiled rules point into them).

        Raises:
            ValueError: an array is missing, extra, or of another shape or dtype than this
                batch's (the message names it).
        """
        live = self._live_arrays()
        rng = {f"random.{k}": v for k, v in rng_arrays(self.random).items()}
        expected = {**live, **rng, **self._scene_arrays()}
        arrays = self._with_node_bits(arrays)
        if set(arrays) != set(expected):
            raise ValueError(
                f"saved batch state holds {sorted(set(arrays) ^ set(expected))} unlike this "
                f"batch: accepted exactly the arrays {sorted(expected)}"
            )
        for name, target in expected.items():
            saved = np.asarray(arrays[name])
            if saved.shape != target.shape or saved.dtype != target.dtype:
                raise ValueError(
                    f"saved batch state {name} is {saved.dtype}{list(saved.shape)}; accepted "
                    f"{target.dtype}{list(target.shape)}"
                )
        set_rng(self.random, {k: arrays[f"random.{k}"] for k in ("key", "pos", "gauss")})
        for name, target in live.items():
            target[...] = arrays[name]
        for e, p in enumerate(self.physics):
            p.place_scene(self.mission.network.nodes_m[e], self.mission.state.current_mps[e])
            scene = np.array(arrays["physics.state"][e])
            mujoco.mj_setState(p.model.ptr, p.data.ptr, scene, PHYSICS_STATE)
            p.meter.work_j[...] = arrays["physics.work_j"][e]

    def _with_node_bits(self, arrays: Mapping[str, np.ndarray]) -> Mapping[str, np.ndarray]:
        """A state saved before the network kept its delivered bits per node gains them as
        the paper's channel counts them (R tau_data per delivery): exact for such a state."""
        if "network.node_bits" in arrays or "network.deliveries" not in arrays:
            return arrays
        deliveries = np.asarray(arrays["network.deliveries"])
        bits = deliveries * self.mission.network.bits_per_delivery
        return {**arrays, "network.node_bits": bits.astype(float)}

    def _scene_arrays(self) -> dict[str, np.ndarray]:
        """Copies of every MuJoCo scene's physics state and meter (none for kinematic)."""
        if not self.physics:
            return {}
        size = mujoco.mj_stateSize(self.physics[0].model.ptr, PHYSICS_STATE)
        scenes = np.empty((self.n_envs, size))
        for p, row in zip(self.physics, scenes, strict=True):
            mujoco.mj_getState(p.model.ptr, p.data.ptr, row, PHYSICS_STATE)
        return {
            "physics.state": scenes,
            "physics.work_j": np.stack([p.meter.work_j for p in self.physics]),
        }

    def _live_arrays(self) -> dict[str, np.ndarray]:
        return live_arrays(self.mission)

    def close(self) -> None:
        if self.stepper is not None:
            self.stepper.close()
            self.stepper = None
        for p in self.physics:
            p.free()
        self.physics = []
