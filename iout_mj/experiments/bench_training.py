"""Benchmarks of training: PPO steps/s against a trivial env, worker-process scaling, peak
memory (parts of `iout-mj bench`)."""

from __future__ import annotations

import subprocess
import sys
import time
from functools import partial
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecNormalize

from iout_mj.envs import MultiAUVEnv
from iout_mj.scenarios import fixed_config
from iout_mj.training import TrainConfig, new_model, vec_env
from iout_mj.training.trainer import make_env

PHYSICS_BATCH = 8
"""Environments per PhysicsVecEnv call in the benchmarks (the training configuration's)."""
REPEATS = 3


def median_rate(fn: Any, repeats: int = REPEATS) -> float:
    """Median of `repeats` measurements of items per second; `fn` returns its item count."""
    rates = []
    for _ in range(repeats):
        t = time.perf_counter()
        n = fn()
        rates.append(n / (time.perf_counter() - t))
    return float(np.median(rates))


class TrivialEnv(gym.Env):
    """Same spaces and episode length as the task, no work: the framework's own ceiling."""

    def __init__(self, n: int, k: int) -> None:
        ref = MultiAUVEnv(backend="kinematic", config=fixed_config(n, k))
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
    and vectorisation (`training.vec_env`: one in-process batch of `n_envs`); None =
    `TrivialEnv` x `n_envs`, in-process too (DummyVecEnv)."""
    cfg = TrainConfig(n_auvs=n, n_nodes=k, n_envs=n_envs)
    torch.set_num_threads(cfg.torch_threads)
    if backend is None:
        inner = DummyVecEnv([partial(TrivialEnv, n, k)] * n_envs)
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
    rate = median_rate(run)
    venv.close()
    return rate


def peak_rss_mb(code: str) -> float:
    """Peak resident memory (VmHWM) of a fresh Python process running `code`."""
    code += "\nprint(open('/proc/self/status').read().split('VmHWM:')[1].split()[0])\n"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return int(out.stdout.split()[-1]) / 1024


def memory_mb(n_envs: int = PHYSICS_BATCH) -> dict[str, float]:
    """Peak resident memory of one MuJoCo env over an episode, and of PPO training on the
    MuJoCo backend as configured (one process: `n_envs` scenes, rollout threads, PPO)."""
    one = peak_rss_mb(
        "import gymnasium as gym, iout_mj\n"
        "env = gym.make('iout_mj/MultiAUV-v0', backend='mujoco', n_auvs=2, n_nodes=7)\n"
        "env.reset(seed=0)\n"
        "for _ in range(55): env.step(env.action_space.sample())\n"
    )
    train = peak_rss_mb(
        "from stable_baselines3.common.vec_env import VecNormalize\n"
        "from iout_mj.training import TrainConfig, new_model, vec_env\n"
        f"cfg = TrainConfig(n_auvs=2, n_nodes=7, n_envs={n_envs}, n_steps=64, batch_size=64)\n"
        f"venv = VecNormalize(vec_env(cfg, 'mujoco', {n_envs}, 0, parallel=True))\n"
        f"new_model(cfg, venv).learn({2 * 64 * n_envs})\n"
    )
    return {"one_env_mb": one, "training_mb": train, "training_envs": n_envs}
