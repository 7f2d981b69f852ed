"""One mission end to end: a policy flies it, metrics and figures are saved, a video is written."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from iout_mj.envs import ENV_ID


def use_bundled_ffmpeg() -> None:
    """Point mediapy at imageio-ffmpeg's static binary unless ffmpeg is on the PATH."""
    import shutil

    import mediapy

    if shutil.which("ffmpeg") is None:
        import imageio_ffmpeg

        mediapy.set_ffmpeg(imageio_ffmpeg.get_ffmpeg_exe())


def load_policy(name: str, env: Any, seed: int = 0) -> Any:
    """A callable `policy(env) -> action`: a baseline name or a trained policy (name or file)."""
    from iout_mj.baselines import POLICIES, make_policy

    if name in POLICIES:
        baseline = make_policy(name, seed)

        def act(e: Any, _obs: np.ndarray) -> np.ndarray:
            return baseline(e.unwrapped.mission)

        act.reset = baseline.reset  # type: ignore[attr-defined]
        return act
    from iout_mj.policies import load_trained_policy

    return load_trained_policy(name, env)


def run_episode(env: Any, policy: Any, seed: int, on_step: Any = None) -> dict[str, Any]:
    """Play one episode; returns its metrics (plus the return)."""
    obs, _ = env.reset(seed=seed)
    if hasattr(policy, "reset"):
        policy.reset(seed)
    ret = 0.0
    while True:
        obs, reward, terminated, truncated, info = env.step(policy(env, obs))
        ret += reward
        if on_step is not None:
            on_step(info)
        if terminated or truncated:
            metrics = dict(info["metrics"])
            metrics["return"] = ret
            if "error" in info:
                metrics["error"] = info["error"]
            return metrics


def run_mission(
    policy: str = "planner",
    n_auvs: int = 2,
    n_nodes: int = 7,
    backend: str = "mujoco",
    seed: int = 0,
    out: Path = Path("renders"),
    video: bool = True,
    width: int = 960,
    height: int = 540,
    fps: int = 30,
    config: str | None = None,
    slots: int | None = None,
    name: str = "mission",
) -> dict[str, Any]:
    """Fly one mission and write `<name>.json`, `<name>_trajectory.png`, and (with `video`)
    `<name>.mp4` plus its last frame `<name>.png` into `out`."""
    import dataclasses

    from iout_mj.envs import resolve_config

    cfg = resolve_config(config, n_auvs, n_nodes, "paper")
    if slots is not None:
        if slots < 1:
            raise ValueError(f"slots={slots}: accepted an integer >= 1")
        cfg = cfg.replace(scenario=dataclasses.replace(cfg.scenario, horizon_slots=slots))
    out.mkdir(parents=True, exist_ok=True)
    env = gym.make(
        ENV_ID,
        backend=backend,
        config=cfg,
        render_mode="rgb_array" if video else None,
        width=width,
        height=height,
    )
    act = load_policy(policy, env, seed)
    writer = None
    bar = tqdm(
        total=cfg.scenario.horizon_slots,
        desc=f"mission {policy} N={n_auvs} K={n_nodes}",
        unit="slot",
    )
    start = time.perf_counter()
    frames = 0
    if video:
        import mediapy

        use_bundled_ffmpeg()
        env.reset(seed=seed)
        env.render()  # builds the renderer
        writer = mediapy.VideoWriter(out / f"{name}.mp4", shape=(height, width), fps=fps)
        writer.__enter__()
    last: list[np.ndarray] = []

    def on_step(info: dict[str, Any]) -> None:
        nonlocal frames, last
        bar.update(1)
        if writer is not None:
            renderer = env.unwrapped._renderer  # type: ignore[attr-defined]
            last = renderer.take_frames()
            for f in last:
                writer.add_image(f)
            frames += len(last)

    try:
        metrics = run_episode(env, act, seed, on_step)
    finally:
        bar.close()
        if writer is not None:
            writer.__exit__(None, None, None)
    elapsed = time.perf_counter() - start
    if writer is not None and last:
        import mediapy

        mediapy.write_image(out / f"{name}.png", last[-1])
    from iout_mj.figures import trajectory_figure

    trace = env.unwrapped.mission.trace()  # type: ignore[attr-defined]
    title = f"{policy}, N={n_auvs}, K={n_nodes}, {backend}"
    trajectory_figure(trace, out / f"{name}_trajectory.png", title=title)
    summary = {
        "policy": policy,
        "n_auvs": n_auvs,
        "n_nodes": n_nodes,
        "backend": backend,
        "seed": seed,
        "metrics": metrics,
        "video_frames": frames,
        "wall_clock_s": round(elapsed, 2),
    }
    (out / f"{name}.json").write_text(json.dumps(summary, indent=2) + "\n")
    env.close()
    return summary
