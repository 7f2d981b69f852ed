"""Train one parameter-shared PPO policy for every AUV on the PettingZoo env (SuperSuit ->
stable-baselines3), then fly it on the MuJoCo backend beside the centralised `ppo-n2-k7`.

    .venv/bin/python training/examples/pettingzoo_shared_ppo.py --steps 600000 --out runs/shared

600,000 agent steps are 300,000 joint steps of the 2 AUVs (the README's run).

Each AUV acts on its own observation (`iout_mj.envs.parallel_env.agent_observations`) with the
same network; the reward is the team's. Evaluation: 20 MuJoCo episodes, seeds 0-19, K = 7.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import supersuit as ss
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.utils import set_random_seed
from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

import iout_mj
from iout_mj.agents.policy_format import Normalizer


def train(steps: int, seed: int) -> tuple[PPO, VecNormalize]:
    set_random_seed(seed)  # SuperSuit's vec env has no seed(): PPO(seed=...) would call it
    env = iout_mj.parallel_env(n_auvs=2, n_nodes=7, backend="kinematic")
    vec = ss.pettingzoo_env_to_vec_env_v1(env)
    vec = ss.concat_vec_envs_v1(vec, 4, num_cpus=0, base_class="stable_baselines3")
    venv = VecNormalize(VecMonitor(vec), gamma=0.99)
    model = PPO(
        "MlpPolicy",
        venv,
        learning_rate=3e-4,
        n_steps=512,
        batch_size=512,
        ent_coef=0.01,
        policy_kwargs={"net_arch": [256, 256]},
        device="cpu",
        verbose=0,
    )
    model.learn(steps, progress_bar=False)
    return model, venv


def evaluate(model: PPO, normalize: Normalizer, episodes: int) -> dict[str, float]:
    env = iout_mj.parallel_env(n_auvs=2, n_nodes=7, backend="mujoco")
    rows = []
    for seed in range(episodes):
        obs, _ = env.reset(seed=seed)
        while env.agents:
            actions = {
                a: model.policy.predict(normalize(o), deterministic=True)[0] for a, o in obs.items()
            }
            obs, *_ = env.step(actions)
        m = env.mission.metrics()
        rows.append(
            {
                "mean_aoi_horizon": m["mean_aoi_horizon"],
                "jain": m["jain"],
                "delivered_mbit": m["delivered_bits"] / 1e6,
                "docked": float(all(m["docked"])),
            }
        )
    return {k: float(np.mean([r[k] for r in rows])) for k in rows[0]} | {
        f"{k}_std": float(np.std([r[k] for r in rows])) for k in rows[0]
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--steps", type=int, default=600_000, help="agent steps of training")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--episodes", type=int, default=20, help="MuJoCo evaluation episodes")
    parser.add_argument("--out", default="runs/pettingzoo-shared", help="folder for result.json")
    args = parser.parse_args()
    torch.set_num_threads(1)
    model, venv = train(args.steps, args.seed)
    result = {"steps": args.steps, "seed": args.seed}
    result.update(evaluate(model, Normalizer.from_vec_normalize(venv), args.episodes))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "result.json").write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
