"""How far the rollout search's motion model is from the physics, one slot at a time.

A policy flies MuJoCo missions; before every slot the mission's state is copied into a one-row
kinematic mission (the model `agents/search.py` rolls out), both fly the slot's action, and each
active AUV's model position is compared with the hull's: the error along the model's track
(positive: the model is ahead) and across it, binned by the current's component along the
track. The README's "Where the targets stand" quotes its run with 1 m/s currents:

    .venv/bin/python training/examples/rollout_model_error.py \
        --config training/configs/env/current-1mps.yaml
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

from iout_mj.agents.policies import load_policy
from iout_mj.agents.search import copy_state
from iout_mj.envs import ENV_ID
from iout_mj.envs.batch import MissionBatch
from iout_mj.scenarios import resolve

BINS_MPS = ((-np.inf, -0.5), (-0.5, 0.5), (0.5, np.inf))
"""Bins of the current's component along the model's track, m/s."""


def slot_errors(policy: str, config: str | None, n_auvs: int, n_nodes: int, seeds: int) -> dict:
    """Per active AUV-slot: the model's error along and across its track (m), its progress and
    the hull's along that track (m), and the current along it (m/s)."""
    spec = resolve(config, n_auvs=n_auvs, n_nodes=n_nodes, layout="paper", backend="mujoco")
    env = gym.make(ENV_ID, backend="mujoco", config=spec)
    fly = load_policy(policy, env)
    model = MissionBatch(1, "kinematic", config=spec.config, observation="tokens")
    mission = env.unwrapped.mission  # type: ignore[attr-defined]
    rows: dict[str, list[float]] = {k: [] for k in ("along", "across", "model", "hull", "current")}
    for seed in range(seeds):
        obs, _ = env.reset(seed=seed)
        done = False
        while not done:
            action = fly(env, obs)
            start = mission.state.positions_m.copy()
            active = ~mission.state.docked.copy()
            copy_state(mission, model)
            model.move(action[None])
            obs, _, terminated, truncated, _ = env.step(action)
            done = terminated or truncated
            predicted, hull = model.mission.state.positions_m[0], mission.state.positions_m
            flying = active & ~mission.state.docked & ~model.mission.state.docked[0]
            for i in np.flatnonzero(flying):
                track = predicted[i] - start[i]
                length = float(np.linalg.norm(track))
                if length < 1.0:
                    continue
                u = track / length
                error = predicted[i] - hull[i]
                rows["along"].append(float(error @ u))
                rows["across"].append(abs(float(u[0] * error[1] - u[1] * error[0])))
                rows["model"].append(length)
                rows["hull"].append(float((hull[i] - start[i]) @ u))
                rows["current"].append(float(np.reshape(mission.state.current_mps, 2) @ u))
    env.close()
    model.close()
    return {k: np.array(v) for k, v in rows.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--policy", default="ppo-general")
    parser.add_argument("--config", default=None, help="an env config (default: the paper's)")
    parser.add_argument("--n-auvs", type=int, default=2)
    parser.add_argument("--nodes", type=int, default=13, help="K, on the paper's layout")
    parser.add_argument("--seeds", type=int, default=5, help="episodes, seeds 0 to this - 1")
    args = parser.parse_args()
    if args.seeds < 1:
        parser.error(f"--seeds {args.seeds}: accepted an integer of at least 1")
    r = slot_errors(args.policy, args.config, args.n_auvs, args.nodes, args.seeds)
    print(
        f"{len(r['along'])} AUV-slots: model ahead along its track by {r['along'].mean():.1f} m "
        f"(90th percentile {np.percentile(r['along'], 90):.1f} m), {r['across'].mean():.1f} m "
        "across it"
    )
    for low, high in BINS_MPS:
        k = (r["current"] >= low) & (r["current"] < high)
        if k.any():
            print(
                f"current along the track in [{low}, {high}) m/s: {k.sum()} AUV-slots, model "
                f"ahead by {r['along'][k].mean():.1f} m; per slot the model moves "
                f"{r['model'][k].mean():.1f} m, the hull {r['hull'][k].mean():.1f} m along it"
            )


if __name__ == "__main__":
    main()
