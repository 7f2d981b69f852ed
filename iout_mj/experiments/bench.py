"""Throughput benchmarks (`iout-mj bench`): every number is a median of repeats in one run, and
the targets are ratios so that they hold on a noisy machine."""

from __future__ import annotations

import os
import platform
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

from iout_mj.backends.mujoco.physics import Stepper
from iout_mj.backends.mujoco.task import substeps_per_slot
from iout_mj.config import Config
from iout_mj.envs import ENV_ID, KinematicVecEnv, MultiAUVEnv, PhysicsVecEnv
from iout_mj.experiments.bench_training import (
    PHYSICS_BATCH,
    REPEATS,
    _worker_rate,
    general_recipe,
    median_rate,
    memory_mb,
    ppo_fps,
    token_ppo_fps,
)
from iout_mj.runtime import usable_cpus
from iout_mj.scenarios import ConfigLike, fixed_config
from iout_mj.types import FloatArray


def _env(backend: str, n: int, k: int, **kw: Any) -> Any:
    return MultiAUVEnv(backend=backend, config=fixed_config(n, k), **kw)


def _random_actions(space: Any, count: int = 64, batch: tuple[int, ...] = ()) -> list[Any]:
    rng = np.random.default_rng(0)
    return [rng.integers(0, space.nvec, size=(*batch, len(space.nvec))) for _ in range(count)]


def _env_pass(env: Any, steps: int) -> Callable[[], int]:
    """A run of `steps` env steps with random valid actions, the same episodes every time."""
    actions = _random_actions(env.action_space)

    def run() -> int:
        env.reset(seed=0)
        for i in range(steps):
            _, _, term, trunc, _ = env.step(actions[i % len(actions)])
            if term or trunc:
                env.reset()
        return steps

    return run


def _env_rate(env: Any, steps: int) -> float:
    run = _env_pass(env, steps)
    run()  # warm up
    return median_rate(run)


def _raw_pass(
    model: Any, inputs: list[tuple[FloatArray, FloatArray]], nstep: int
) -> Callable[[], int]:
    """Plain mj_step(nstep) from recorded (start state, control) pairs, one slot each."""
    data = mujoco.MjData(model)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS

    def run() -> int:
        for state, ctrl in inputs:
            mujoco.mj_setState(model, data, state, spec)
            data.ctrl[:] = ctrl
            mujoco.mj_step(model, data, nstep)
        return len(inputs)

    return run


def _paired(env_run: Callable[[], int], raw_run: Callable[[], int]) -> dict[str, float]:
    """Env and raw rates measured alternately (so that machine noise hits both alike); the
    ratio is the median of the per-pair ratios."""
    env_run(), raw_run()  # warm up
    pairs = []
    for _ in range(2 * REPEATS - 1):
        pairs.append((median_rate(env_run, 1), median_rate(raw_run, 1)))
    env, raw = np.array(pairs).T
    return {
        "env_steps_per_s": float(np.median(env)),
        "raw_slots_per_s": float(np.median(raw)),
        "ratio": float(np.median(env / raw)),
    }


def _recorded(stepper: Stepper, calls: Callable[[], Any]) -> list[tuple[FloatArray, FloatArray]]:
    """Run `calls` once, keeping every env's (start state, control) of every rollout."""
    stepper.recorded = []
    try:
        calls()
        return stepper.recorded
    finally:
        stepper.recorded = None


def slot_vs_raw(n: int, k: int, slots: int = 40) -> dict[str, float]:
    """MuJoCo env steps/s over plain mj_step(nstep) on the same model from the same states
    with the same controls (so both do the same physics work): one env through gymnasium and
    dm_control, and a `PhysicsVecEnv` batch on one thread."""
    env = _env("mujoco", n, k)
    model = env.physics.model.ptr
    nstep = substeps_per_slot(env.cfg, env.physics.dt_s)
    run = _env_pass(env, slots)
    single = _paired(run, _raw_pass(model, _recorded(env.physics.stepper, run), nstep))
    env.close()

    venv = PhysicsVecEnv(PHYSICS_BATCH, config=fixed_config(n, k), seed=0)
    actions = _random_actions(venv.action_space, 16, (PHYSICS_BATCH,))
    calls = max(slots // PHYSICS_BATCH, 4)

    def batch_run() -> int:
        venv.seed(0)
        venv.reset()
        for i in range(calls):
            venv.step(actions[i % len(actions)])
        return calls * PHYSICS_BATCH

    batch = _paired(batch_run, _raw_pass(model, _recorded(venv.stepper, batch_run), nstep))
    venv.close()
    return {**single, **{f"batch_{PHYSICS_BATCH}_{key}": v for key, v in batch.items()}}


KINEMATIC_BATCH = 64
"""Environments per KinematicVecEnv call in the kinematic benchmark (and about what PPO uses)."""


REALISTIC_CHANNEL = (
    Path(__file__).resolve().parents[2] / "training/configs/env/realistic-channel.yaml"
)
"""The shipped realistic channel (a source checkout's), whose speed `run` measures too."""


def kinematic_rate(n: int, k: int, steps: int = 3000, base: ConfigLike = None) -> dict[str, float]:
    """Kinematic env steps/s on one core: one env through `gymnasium.make` (its wrappers
    included), and a batch of `KINEMATIC_BATCH` envs through `KinematicVecEnv` (the backend PPO
    trains on); `base`: the env config (default the paper's)."""
    cfg = fixed_config(n, k, base)
    single = _env_rate(gym.make(ENV_ID, backend="kinematic", config=cfg), steps)
    venv = KinematicVecEnv(KINEMATIC_BATCH, config=cfg, seed=0)
    actions = _random_actions(venv.action_space, 16, (KINEMATIC_BATCH,))
    calls = max(steps // KINEMATIC_BATCH, 20)

    def run() -> int:
        venv.reset()
        for i in range(calls):
            venv.step(actions[i % len(actions)])
        return calls * KINEMATIC_BATCH

    run()
    return {"single_env": single, f"batch_{KINEMATIC_BATCH}": median_rate(run)}


def render_fps(frames: int = 16) -> float:
    """Frames/s of the composed 640x480 view (top-down + chase, trails, links, overlay)."""
    env = _env("mujoco", 2, 7, render_mode="rgb_array", width=640, height=480)
    env.reset(seed=0)
    env.render()  # starts the renderer, which then records trails at every step
    rng = np.random.default_rng(0)
    for _ in range(5):
        env.step(rng.integers(0, env.action_space.nvec))

    def run() -> int:
        for _ in range(frames):
            env.render()
        return frames

    rate = median_rate(run)
    env.close()
    return rate


def thread_scaling(n: int, k: int, calls: int = 5) -> float:
    """PhysicsVecEnv steps/s on two rollout threads over one (both in one process)."""
    rates = []
    for nthread in (0, min(2, usable_cpus())):
        venv = PhysicsVecEnv(PHYSICS_BATCH, config=fixed_config(n, k), seed=0, nthread=nthread)
        actions = _random_actions(venv.action_space, 16, (PHYSICS_BATCH,))
        venv.reset()

        def run() -> int:
            for i in range(calls):
                venv.step(actions[i % len(actions)])  # noqa: B023 (called within the loop)
            return calls * PHYSICS_BATCH

        run()
        rates.append(median_rate(run))
        venv.close()
    return rates[1] / rates[0]


def run_all(quick: bool = False, say: Callable[[str], None] = lambda _: None) -> dict[str, Any]:
    """Every benchmark; `quick` shrinks repeats for tests; `say(stage)` before each stage."""
    cfg = Config()
    sizes = [(1, 7), (2, 7), (2, 13), (4, 13)] if not quick else [(2, 7)]
    result: dict[str, Any] = {
        "machine": {
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "processor": platform.machine(),
        },
        "timestep_s": cfg.physics.timestep_s,
        "substeps_per_slot": round(cfg.scenario.slot_s / cfg.physics.timestep_s),
    }
    say("slot_vs_raw (MuJoCo env vs plain mj_step)")
    result["slot_vs_raw"] = {f"N{n}_K{k}": slot_vs_raw(n, k, 10 if quick else 40) for n, k in sizes}
    say("kinematic steps/s")
    kin = {
        f"N{n}_K{k}": kinematic_rate(n, k, 300 if quick else 3000)
        for n, k in ([(2, 13)] if quick else [(1, 7), (1, 13), (2, 7), (2, 13), (4, 7), (4, 13)])
    }
    result["kinematic_steps_per_s"] = {key: v[f"batch_{KINEMATIC_BATCH}"] for key, v in kin.items()}
    result["kinematic_single_env_steps_per_s"] = {key: v["single_env"] for key, v in kin.items()}
    result["kinematic_batch"] = KINEMATIC_BATCH
    if REALISTIC_CHANNEL.is_file():  # a source checkout
        say("kinematic steps/s under the realistic channel")
        channel = kinematic_rate(2, 13, 300 if quick else 3000, REALISTIC_CHANNEL)
        result["kinematic_realistic_channel_steps_per_s"] = {
            "N2_K13": channel[f"batch_{KINEMATIC_BATCH}"],
            "N2_K13_single_env": channel["single_env"],
        }
    result["physics_batch"] = PHYSICS_BATCH
    n_envs, rollouts = (2, 1) if quick else (PHYSICS_BATCH, 2)
    rollout_steps = {"n_steps": 64} if quick else {}  # else the training configuration's
    fps = {}
    for backend in ("mujoco", "kinematic", None):
        say(f"PPO steps/s on {backend or 'a trivial env'}")
        fps[backend] = ppo_fps(backend, 2, 7, n_envs, rollouts, **rollout_steps)
    result["ppo_fps"] = {
        "physics": fps["mujoco"],
        "kinematic": fps["kinematic"],
        "trivial": fps[None],
    }
    result["ppo_fps_ratio"] = fps["mujoco"] / fps[None]
    recipe = general_recipe(quick)
    tokens = {}
    for backend in ("kinematic", "mujoco", None):
        say(f"general recipe PPO steps/s on {backend or 'a trivial env'}")
        tokens[backend or "trivial"] = token_ppo_fps(backend, recipe, 1 if quick else 2)
    result["token_ppo_steps_per_s"] = tokens
    result["token_ppo_ratio"] = tokens["kinematic"] / tokens["trivial"]
    steps = 10 if quick else 60
    say("worker-process scaling")
    one, two = _worker_rate(1, 2, 7, steps), _worker_rate(2, 2, 7, steps)
    result["subproc_scaling"] = two / one
    say("rollout-thread scaling")
    result["thread_scaling"] = thread_scaling(2, 7, 2 if quick else 5)
    say("render frames/s")
    result["render_fps"] = render_fps(4 if quick else 16)
    say("peak memory")
    result["memory"] = memory_mb(2 if quick else PHYSICS_BATCH)
    return result
