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


def _env_rate(env: Any, steps: int) -> float:
    rng = np.random.default_rng(0)
    actions = [rng.integers(0, env.action_space.nvec) for _ in range(64)]
    env.reset(seed=0)

    def run() -> int:
        for i in range(steps):
            _, _, term, trunc, _ = env.step(actions[i % 64])
            if term or trunc:
                env.reset()
        return steps

    run()  # warm up
    return _median_rate(run)


def slot_vs_raw(n: int, k: int, slots: int = 40) -> dict[str, float]:
    """Env steps/s of the MuJoCo backend over plain mj_step(nstep) on the same model."""
    import mujoco

    env = _env("mujoco", n, k)
    physics = env.physics
    m, nstep = physics.model.ptr, env._env._n_sub_steps
    env_rate = _env_rate(env, slots)
    d = mujoco.MjData(m)
    d.qpos[:] = physics.data.qpos
    d.ctrl[:] = physics.data.ctrl

    def raw() -> int:
        for _ in range(slots):
            mujoco.mj_step(m, d, nstep)
        return slots

    raw()
    raw_rate = _median_rate(raw)
    env.close()
    return {"env_steps_per_s": env_rate, "raw_slots_per_s": raw_rate, "ratio": env_rate / raw_rate}


def kinematic_rate(n: int, k: int, steps: int = 3000) -> float:
    return _env_rate(_env("kinematic", n, k), steps)


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


def ppo_fps(
    backend: str | None, n: int, k: int, n_envs: int, n_steps: int, rollouts: int = 2
) -> float:
    """PPO steps/s (collection + updates) with SubprocVecEnv workers; None = trivial env."""
    from functools import partial

    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import SubprocVecEnv, VecNormalize

    from iout_mj.training import TrainConfig, make_env

    torch.set_num_threads(1)
    batch = min(512, n_envs * n_steps)
    cfg = TrainConfig(n_auvs=n, n_nodes=k, n_envs=n_envs, n_steps=n_steps, batch_size=batch)
    fns: list[Any] = [
        partial(make_env, cfg, backend, i) if backend else partial(TrivialEnv, n, k)
        for i in range(n_envs)
    ]
    venv = VecNormalize(SubprocVecEnv(fns, start_method="spawn"))
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=n_steps,
        batch_size=batch,
        n_epochs=10,
        device="cpu",
        policy_kwargs={"net_arch": [256, 256]},
        verbose=0,
        seed=0,
    )
    model.learn(n_envs * n_steps)  # warm up (worker start, first update)
    t = time.perf_counter()
    model.learn(rollouts * n_envs * n_steps, reset_num_timesteps=False)
    fps = rollouts * n_envs * n_steps / (time.perf_counter() - t)
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
    result["kinematic_steps_per_s"] = {
        f"N{n}_K{k}": kinematic_rate(n, k, 300 if quick else 3000)
        for n, k in ([(2, 13)] if quick else [(1, 7), (1, 13), (2, 7), (2, 13), (4, 7), (4, 13)])
    }
    n_envs, n_steps = (2, 64) if quick else (8, 512)
    physics_fps = ppo_fps("mujoco", 2, 7, n_envs, n_steps, rollouts=1 if quick else 2)
    trivial_fps = ppo_fps(None, 2, 7, n_envs, n_steps, rollouts=1 if quick else 2)
    result["ppo_fps"] = {"physics": physics_fps, "trivial": trivial_fps}
    result["ppo_fps_ratio"] = physics_fps / trivial_fps
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
    lines.append("kinematic_steps_per_s (one core; target >= 15000 for N2_K13)")
    for key, v in r["kinematic_steps_per_s"].items():
        lines.append(f"  {key:<7} {v:10.0f}")
    lines.append(
        f"ppo_fps_ratio {r['ppo_fps_ratio']:.3f} (physics {r['ppo_fps']['physics']:.0f}"
        f" / trivial {r['ppo_fps']['trivial']:.0f} steps/s; target >= 0.6)"
    )
    lines.append(f"subproc_scaling {r['subproc_scaling']:.3f} (2 workers / 1; target >= 1.8)")
    lines.append(f"render_fps {r['render_fps']:.1f} (640x480, top-down + chase, overlays)")
    mem = r["memory"]
    lines.append(
        f"memory: one env {mem['one_env_mb']:.0f} MB; training with "
        f"{mem['training_workers']} workers {mem['training_mb']:.0f} MB"
    )
    return "\n".join(lines)
