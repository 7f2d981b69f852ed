"""The warp backend's benchmark (`iout-mj bench --warp`): env steps/s of a WarpVecEnv for
several batch sizes, the raw `mujoco_warp.step` rate over the same substeps (their ratio is
what the mission, the meters and the host transfers cost), and PPO steps/s on it with SB3 on
the same device. On Warp's CPU device use small sizes: a slot of 500 substeps costs seconds."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import torch
from stable_baselines3.common.vec_env import VecNormalize

from iout_mj.backends.mujoco.warp_stepper import default_device
from iout_mj.envs import WarpVecEnv
from iout_mj.scenarios import fixed_config
from iout_mj.training.config import TrainConfig
from iout_mj.training.trainer import new_model

GPU_SIZES = (256, 1024, 4096, 16384)
CPU_SIZES = (4, 16)


def env_rate(b: int, slots: int) -> dict[str, float]:
    """Env steps/s of B scenes (N = 2, K = 7) and raw substep rate of the same worlds."""
    venv = WarpVecEnv(b, config=fixed_config(2, 7), seed=0)
    venv.reset()
    rng = np.random.default_rng(0)
    actions = [rng.integers(0, venv.action_space.nvec, size=(b, 8)) for _ in range(slots + 1)]
    venv.step(actions[0])  # builds the device model (and the CUDA graph)
    t = time.perf_counter()
    for a in actions[1:]:
        venv.step(a)
    env_s = time.perf_counter() - t
    stepper, substeps = venv.stepper, venv.batch.substeps
    t = time.perf_counter()
    for _ in range(slots):
        stepper._run(substeps)
    stepper.wp.synchronize_device(stepper.device)
    raw_s = time.perf_counter() - t
    venv.close()
    return {
        "env_steps_per_s": b * slots / env_s,
        "raw_slots_per_s": b * slots / raw_s,
        "ratio": raw_s / env_s,
    }


def ppo_rate(b: int, device: str, rollouts: int = 2) -> float:
    """PPO steps/s on a WarpVecEnv of B scenes, SB3 on `device` ('cuda' or 'cpu')."""
    cfg = TrainConfig(n_auvs=2, n_nodes=7, n_envs=b, n_steps=8, batch_size=b * 8)
    venv = VecNormalize(WarpVecEnv(b, config=fixed_config(2, 7), seed=0), gamma=cfg.gamma)
    model = new_model(cfg, venv, device=device)
    model.learn(b * cfg.n_steps)  # warm up
    t = time.perf_counter()
    model.learn(rollouts * b * cfg.n_steps, reset_num_timesteps=False)
    fps = rollouts * b * cfg.n_steps / (time.perf_counter() - t)
    venv.close()
    return fps


def run(
    sizes: Sequence[int] | None = None, quick: bool = False, say: Callable[[str], None] = print
) -> dict[str, Any]:
    """The warp benchmark on the device Warp finds; `quick` times one slot and no PPO (a smoke
    test: on Warp's CPU device every slot costs seconds; tests train PPO on warp apart)."""
    slots = 1 if quick else 2
    device = default_device()
    sizes = sizes or (GPU_SIZES if device == "cuda" else CPU_SIZES)
    torch_device = "cuda" if device == "cuda" and torch.cuda.is_available() else "cpu"
    result: dict[str, Any] = {"device": device, "sb3_device": torch_device, "sizes": {}}
    for b in sizes:
        say(f"warp env and raw steps/s, B = {b}")
        result["sizes"][str(b)] = env_rate(b, slots)
    result["ppo_batch"] = sizes[-1]
    result["ppo_steps_per_s"] = None
    if not quick:
        say(f"PPO steps/s on the warp backend, B = {sizes[-1]}")
        result["ppo_steps_per_s"] = ppo_rate(sizes[-1], torch_device)
    return result


def format_table(r: dict[str, Any]) -> str:
    lines = [f"warp backend on {r['device']} (N = 2, K = 7, 500 substeps per slot)"]
    for b, v in r["sizes"].items():
        lines.append(
            f"  B {b:>6}: env {v['env_steps_per_s']:10.1f} steps/s, raw mjw.step "
            f"{v['raw_slots_per_s']:10.1f} slots/s, ratio {v['ratio']:.3f}"
        )
    ppo = r["ppo_steps_per_s"]
    lines.append(
        f"  PPO on B = {r['ppo_batch']} (SB3 on {r['sb3_device']}): "
        + (f"{ppo:.1f} steps/s" if ppo is not None else "not measured (--quick)")
    )
    return "\n".join(lines)
