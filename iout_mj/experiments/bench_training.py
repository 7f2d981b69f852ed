"""Benchmarks of training: PPO steps/s against a trivial env (the specialists' MLP and the
general recipe's token network), worker-process scaling, peak memory (parts of
`iout-mj bench`)."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
import time
from functools import partial
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecNormalize

from iout_mj.envs import MultiAUVEnv
from iout_mj.envs.vec_env import BatchedVecEnv
from iout_mj.errors import UsageError
from iout_mj.scenarios import fixed_config
from iout_mj.training import TrainConfig, new_model, vec_env
from iout_mj.training.trainer import make_env, phase_model, torch_setup

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


def ppo_fps(
    backend: str | None,
    n: int,
    k: int,
    n_envs: int,
    rollouts: int = 2,
    n_steps: int = TrainConfig.n_steps,
) -> float:
    """PPO steps/s (collection + updates) with the training configuration's hyperparameters
    (rollouts of `n_steps` per env, its minibatch size at most) and vectorisation
    (`training.vec_env`: one in-process batch of `n_envs`); None = `TrivialEnv` x `n_envs`,
    in-process too (DummyVecEnv)."""
    batch_size = min(TrainConfig.batch_size, n_envs * n_steps)
    cfg = TrainConfig(n_auvs=n, n_nodes=k, n_envs=n_envs, n_steps=n_steps, batch_size=batch_size)
    torch_setup(cfg)
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


GENERAL_RECIPE = Path(__file__).resolve().parents[2] / "training/configs/ppo-general-n2.yaml"
"""The general recipe whose PPO speed `token_ppo_fps` measures (a source checkout's)."""


class ConstantVecEnv(BatchedVecEnv):
    """Fixed observations, zero reward, episodes of the task's length: what PPO costs with an
    env that costs nothing (the framework's ceiling for the same spaces and network)."""

    def __init__(self, obs: np.ndarray, spaces: tuple[Any, Any], horizon: int):
        super().__init__(len(obs), *spaces)
        self._obs, self._horizon, self._t = obs, horizon, 0
        self.render_mode = None

    def reset(self) -> Any:
        self._t = 0
        return self._obs.copy()

    def step_async(self, actions: np.ndarray) -> None:
        self._t += 1

    def step_wait(self) -> Any:
        done = self._t >= self._horizon
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if done:
            self._t = 0
            for info in infos:
                info["terminal_observation"] = self._obs[0]
        dones = np.full(self.num_envs, done)
        return self._obs.copy(), np.zeros(self.num_envs, np.float32), dones, infos

    def close(self) -> None:
        pass


def general_recipe(quick: bool = False) -> TrainConfig:
    """The general recipe's training config (`quick`: rollouts of 16 steps and one torch
    thread, for tests run beside others: two threads per process on a busy 2-core machine made
    PPO about 15x slower)."""
    if not GENERAL_RECIPE.is_file():
        raise UsageError(
            f"the general recipe {GENERAL_RECIPE.name} is not here: the token PPO benchmark "
            "runs from a source checkout (training/configs beside the package)"
        )
    cfg = TrainConfig.load(GENERAL_RECIPE)
    return dataclasses.replace(cfg, n_steps=16, batch_size=144, torch_threads=1) if quick else cfg


def token_ppo_fps(backend: str | None, cfg: TrainConfig, rollouts: int = 2) -> float:
    """PPO steps/s (collection + updates) of the general recipe `cfg` (its token network,
    scenario cells, hyperparameters and torch threads) on `backend`; None = `ConstantVecEnv`
    holding the cells' first observations (the same node counts, so the same network cost)."""
    torch_setup(cfg)
    real = vec_env(cfg, backend or "kinematic", cfg.n_envs, cfg.seed, parallel=True)
    if backend is None:
        obs = real.reset()
        spaces = (real.observation_space, real.action_space)
        real.close()
        real = ConstantVecEnv(obs, spaces, cfg.env.scenario.horizon_slots)
    model = phase_model(None, cfg, real)
    rollout = real.num_envs * cfg.n_steps
    model.learn(rollout)  # warm up
    t = time.perf_counter()
    model.learn(rollouts * rollout, reset_num_timesteps=False)
    fps = rollouts * rollout / (time.perf_counter() - t)
    model.get_env().close()
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
