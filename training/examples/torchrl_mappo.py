"""Train MAPPO (or IPPO) on the PettingZoo env with TorchRL, then fly the exported team policy
beside greedy for N = 2 to 4 (each AUV acting on its own observation).

    .venv/bin/python training/examples/torchrl_mappo.py --config training/configs/mappo-n2.yaml \\
        --steps 450000 --out runs/mappo-example

Needs the `mappo` extra (`pip install -e ".[mappo]"`). The same run as `iout-mj train-marl
CONFIG --steps S --out OUT`; the evaluation is `iout-mj evaluate --policy greedy OUT/policy
--n-auvs 2 3 4 --nodes ... --layout random --backend kinematic`. Results: OUT/curve.json (the
learning curve against greedy on the same held-out episodes) and OUT/evaluation.json.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np

from iout_mj.agents.policies import load_policy
from iout_mj.agents.rollout import run_episode
from iout_mj.envs import ENV_ID
from iout_mj.training.marl import MarlConfig, MarlPhase, train_marl


def fly(policy_name: str, n: int, k: int, episodes: int) -> dict[str, float]:
    """Mean AoI over T_max and the share of episodes with every AUV docked."""
    aoi, docked = [], []
    for seed in range(episodes):
        env = gym.make(ENV_ID, backend="kinematic", n_auvs=n, n_nodes=k, layout="random")
        metrics = run_episode(env, load_policy(policy_name, env, seed), seed)
        aoi.append(metrics["mean_aoi_horizon"])
        docked.append(float(all(metrics["docked"])))
        env.close()
    return {"mean_aoi_horizon": float(np.mean(aoi)), "docked_rate": float(np.mean(docked))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--config", default="training/configs/mappo-n2.yaml")
    parser.add_argument("--steps", type=int, help="agent steps of one kinematic phase")
    parser.add_argument("--episodes", type=int, default=10, help="evaluation episodes per cell")
    parser.add_argument("--out", default="runs/mappo-example")
    args = parser.parse_args()
    cfg = MarlConfig.load(args.config)
    if args.steps is not None:
        cfg = replace(cfg, phases=(MarlPhase("kinematic", args.steps),))
    out = Path(args.out)
    summary = train_marl(cfg, out)
    policy = str(out / "policy")
    k = cfg.node_range[1]
    rows = [
        {"policy": name, "n_auvs": n, "n_nodes": k, **fly(name, n, k, args.episodes)}
        for n in range(2, cfg.n_max + 1)
        for name in ("greedy", policy)
    ]
    (out / "evaluation.json").write_text(json.dumps(rows, indent=2) + "\n")
    print(json.dumps({"training": summary, "evaluation": rows}, indent=2))


if __name__ == "__main__":
    main()
