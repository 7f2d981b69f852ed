"""Throughput benchmarks (`iout-mj bench`): every number is a median of repeats in one run, and
the targets are ratios so that they hold on a noisy machine."""

from __future__ import annotations

import os
import platform
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

REPEATS = 3


def _median_rate(fn: Callable[[], int], repeats: int = REPEATS) -> float:
    """Median of `repeats` measurements of items per second; `fn` returns its item count."""
    rates = []
    for _ in range(repeats):
        t = time.perf_counter()
        n = fn()
        rates.append(n / (time.perf_counter() - t))
    return float(np.median(rates))


def _env(backend: str, n: int, k: int, **kw: Any) -> Any:
    from iout_mj.envs import MultiAUVEnv
    from iout_mj.evaluation import scenario_config

    return MultiAUVEnv(backend=backend, config=scenario_config(n, k), **kw)


def _random_actions(space: Any, count: int = 64, batch: tuple[int, ...] = ()) -> list[Any]:
    rng = np.random.default_rng(0)
    return [rng.integers(0, space.nvec, size=(*batch, len(space.nvec))) for _ in range(count)]


def _env_rate(env: Any, steps: int) -> float:
    """Env steps/s with random valid actions; every repeat replays the same episodes."""
    actions = _random_actions(env.action_space)

    def run() -> int:
        env.reset(seed=0)
        for i in range(steps):
            _, _, term, trunc, _ = env.step(actions[i % len(actions)])
            if term or trunc:
                env.reset()
        return steps

    run()  # warm up
    return _median_rate(run)


def slot_vs_raw(n: int, k: int, slots: int = 40) -> dict[str, float]:
    """Env steps/s of the MuJoCo backend over plain mj_step(nstep) on the same model, from
    the same states with the same controls (so both do the same physics work)."""
    import mujoco

    env = _env("mujoco", n, k)
    physics = env.physics
    m, d, nstep = physics.model.ptr, physics.data.ptr, env._env._n_sub_steps
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    starts, ctrls = np.empty((slots, mujoco.mj_stateSize(m, spec))), np.empty((slots, m.nu))
    actions = _random_actions(env.action_space)
    env.reset(seed=0)
    for i in range(slots):  # record every slot's start state and control (same as _env_rate)
        mujoco.mj_getState(m, d, starts[i], spec)
        _, _, term, trunc, _ = env.step(actions[i % len(actions)])
        ctrls[i] = d.ctrl
        if term or trunc:
            env.reset()
    env_rate = _env_rate(env, slots)
    raw_data = mujoco.MjData(m)

    def raw() -> int:
        for i in range(slots):
            mujoco.mj_setState(m, raw_data, starts[i], spec)
            raw_data.ctrl[:] = ctrls[i]
            mujoco.mj_step(m, raw_data, nstep)
        return slots

    raw()
    raw_rate = _median_rate(raw)
    env.close()
    return {"env_steps_per_s": env_rate, "raw_slots_per_s": raw_rate, "ratio": env_rate / raw_rate}


KINEMATIC_BATCH = 64
"""Environments per KinematicVecEnv call in the kinematic benchmark (and about what PPO uses)."""


def kinematic_rate(n: int, k: int, steps: int = 3000) -> dict[str, float]:
    """Kinematic env steps/s on one core: one env through the gymnasium API, and a batch of
    `KINEMATIC_BATCH` envs through `KinematicVecEnv` (the backend PPO trains on)."""
    from iout_mj.evaluation import scenario_config
    from iout_mj.vec_env import KinematicVecEnv

    single = _env_rate(_env("kinematic", n, k), steps)
    venv = KinematicVecEnv(KINEMATIC_BATCH, config=scenario_config(n, k), seed=0)
    actions = _random_actions(venv.action_space, 16, (KINEMATIC_BATCH,))
    calls = max(steps // KINEMATIC_BATCH, 20)

    def run() -> int:
        venv.reset()
        for i in range(calls):
            venv.step(actions[i % len(actions)])
        return calls * KINEMATIC_BATCH

    run()
    return {"single_env": single, f"batch_{KINEMATIC_BATCH}": _median_rate(run)}


class TrivialEnv(gym.Env):
    """Same spaces and episode length as the task, no work: the framework's own ceiling."""

    def __init__(self, n: int, k: int) -> None:
        ref = _env("kinematic", n, k)
        self.action_space = ref.action_space
        self.observation_space = ref.observation_space
        self._obs = np.zeros(ref.observation_space.shape or (), dtype=np.float32)
        self._horizon = ref.cfg.scenario.horizon_slots
        self._t = 0

    def reset(self, *, seed: int | None = None, options: Any = None) -> Any:
        super().reset(seed=seed)
        self._t = 0
        return self._obs, {}

    def step(self, action: Any) -> Any:
        self._t += 1
        return self._obs, 0.0, False, self._t >= self._horizon, {}


def ppo_fps(backend: str | None, n: int, k: int, n_envs: int, rollouts: int = 2) -> float:
    """PPO steps/s (collection + updates) with the training configuration's hyperparameters
    and vectorisation (`training.vec_env`: MuJoCo in worker processes, the kinematic batch in
    this one); None = `TrivialEnv` in as many worker processes."""
    from functools import partial

    import torch
    from stable_baselines3.common.vec_env import SubprocVecEnv, VecNormalize

    from iout_mj.training import TrainConfig, new_model, vec_env

    cfg = TrainConfig(n_auvs=n, n_nodes=k, n_envs=n_envs)
    torch.set_num_threads(cfg.torch_threads)
    if backend is None:
        fns: list[Any] = [partial(TrivialEnv, n, k)] * n_envs
        inner = SubprocVecEnv(fns, start_method="spawn")
    else:
        inner = vec_env(cfg, backend, n_envs, cfg.seed, parallel=True)
    venv = VecNormalize(inner, gamma=cfg.gamma)
    model = new_model(cfg, venv)
    rollout = n_envs * cfg.n_steps
    model.learn(rollout)  # warm up (worker start, first update)
    t = time.perf_counter()
    model.learn(rollouts * rollout, reset_num_timesteps=False)
    fps = rollouts * rollout / (time.perf_counter() - t)
    venv.close()
    return fps


def _worker_rate(workers: int, n: int, k: int, steps: int) -> float:
    from functools import partial

    from stable_baselines3.common.vec_env import SubprocVecEnv

    from iout_mj.training import TrainConfig, make_env

    cfg = TrainConfig(n_auvs=n, n_nodes=k)
    venv = SubprocVecEnv(
        [partial(make_env, cfg, "mujoco", i) for i in range(workers)], start_method="spawn"
    )
    venv.reset()
    rng = np.random.default_rng(0)
    nvec = venv.action_space.nvec  # type: ignore[attr-defined]

    def run() -> int:
        for _ in range(steps):
            venv.step(rng.integers(0, nvec, size=(workers, len(nvec))))
        return steps * workers

    run()
    rate = _median_rate(run)
    venv.close()
    return rate


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

    rate = _median_rate(run)
    env.close()
    return rate


def _rss_mb(pids: list[int]) -> float:
    total = 0
    for pid in pids:
        try:
            with open(f"/proc/{pid}/status") as f:
                text = f.read()
            total += int(text.split("VmRSS:")[1].split()[0])
        except (OSError, IndexError):
            pass
    return total / 1024


def memory_mb(n_envs: int = 8) -> dict[str, float]:
    """Resident memory of one MuJoCo env (this process) and of a training setup with workers."""
    import subprocess
    import sys

    code = (
        "import gymnasium as gym, iout_mj\n"
        "env = gym.make('iout_mj/MultiAUV-v0', backend='mujoco', n_auvs=2, n_nodes=7)\n"
        "env.reset(seed=0)\n"
        "for _ in range(55): env.step(env.action_space.sample())\n"
        "print(open('/proc/self/status').read().split('VmHWM:')[1].split()[0])\n"
    )
    one = (
        int(
            subprocess.run(
                [sys.executable, "-c", code], capture_output=True, text=True, check=True
            ).stdout.split()[-1]
        )
        / 1024
    )
    from functools import partial

    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import SubprocVecEnv, VecNormalize

    from iout_mj.training import TrainConfig, make_env

    cfg = TrainConfig(n_auvs=2, n_nodes=7)
    venv = VecNormalize(
        SubprocVecEnv(
            [partial(make_env, cfg, "mujoco", i) for i in range(n_envs)], start_method="spawn"
        )
    )
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=64,
        batch_size=64,
        device="cpu",
        verbose=0,
        policy_kwargs={"net_arch": [256, 256]},
    )
    model.learn(n_envs * 64)
    pids = [os.getpid()] + [p.pid for p in venv.venv.processes]  # type: ignore[attr-defined]
    train = _rss_mb(pids)
    venv.close()
    return {"one_env_mb": one, "training_mb": train, "training_workers": n_envs}


def run_all(quick: bool = False) -> dict[str, Any]:
    """Every benchmark; `quick` shrinks repeats for tests."""
    from iout_mj.config import Config

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
    result["slot_vs_raw"] = {f"N{n}_K{k}": slot_vs_raw(n, k, 10 if quick else 40) for n, k in sizes}
    kin = {
        f"N{n}_K{k}": kinematic_rate(n, k, 300 if quick else 3000)
        for n, k in ([(2, 13)] if quick else [(1, 7), (1, 13), (2, 7), (2, 13), (4, 7), (4, 13)])
    }
    result["kinematic_steps_per_s"] = {key: v[f"batch_{KINEMATIC_BATCH}"] for key, v in kin.items()}
    result["kinematic_single_env_steps_per_s"] = {key: v["single_env"] for key, v in kin.items()}
    result["kinematic_batch"] = KINEMATIC_BATCH
    n_envs, rollouts = (2, 1) if quick else (8, 2)
    fps = {b: ppo_fps(b, 2, 7, n_envs, rollouts) for b in ("mujoco", "kinematic", None)}
    result["ppo_fps"] = {
        "physics": fps["mujoco"],
        "kinematic": fps["kinematic"],
        "trivial": fps[None],
    }
    result["ppo_fps_ratio"] = fps["mujoco"] / fps[None]
    steps = 10 if quick else 60
    one, two = _worker_rate(1, 2, 7, steps), _worker_rate(2, 2, 7, steps)
    result["subproc_scaling"] = two / one
    result["render_fps"] = render_fps(4 if quick else 16)
    result["memory"] = memory_mb(2 if quick else 8)
    return result


def format_table(r: dict[str, Any]) -> str:
    lines = [
        f"machine: {r['machine']['cpus']} CPUs, Python {r['machine']['python']}; physics "
        f"dt {r['timestep_s']} s, {r['substeps_per_slot']} substeps per 25 s slot",
        "",
    ]
    lines.append("slot_vs_raw (MuJoCo env steps/s over plain mj_step(nstep); target >= 0.9)")
    for key, v in r["slot_vs_raw"].items():
        lines.append(
            f"  {key:<7} env {v['env_steps_per_s']:8.1f} /s   raw "
            f"{v['raw_slots_per_s']:8.1f} /s   ratio {v['ratio']:.3f}"
        )
    lines.append(
        f"kinematic_steps_per_s (one core, KinematicVecEnv of {r['kinematic_batch']} envs; "
        "target >= 15000 for N2_K13) [one env through gymnasium]"
    )
    for key, v in r["kinematic_steps_per_s"].items():
        lines.append(f"  {key:<7} {v:10.0f}   [{r['kinematic_single_env_steps_per_s'][key]:7.0f}]")
    p = r["ppo_fps"]
    lines.append(
        f"ppo_fps_ratio {r['ppo_fps_ratio']:.3f} (physics {p['physics']:.0f} / trivial "
        f"{p['trivial']:.0f} steps/s; target >= 0.6); kinematic batch {p['kinematic']:.0f} steps/s"
    )
    lines.append(f"subproc_scaling {r['subproc_scaling']:.3f} (2 workers / 1; target >= 1.8)")
    lines.append(f"render_fps {r['render_fps']:.1f} (640x480, top-down + chase, overlays)")
    mem = r["memory"]
    lines.append(
        f"memory: one env {mem['one_env_mb']:.0f} MB; training with "
        f"{mem['training_workers']} workers {mem['training_mb']:.0f} MB"
    )
    return "\n".join(lines)
