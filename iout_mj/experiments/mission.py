"""One mission end to end: a policy flies it, metrics and figures are saved, a video is written."""

from __future__ import annotations

import json
import math
import shutil
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import imageio_ffmpeg
import mediapy
import numpy as np
from tqdm import tqdm

from iout_mj.agents.policies import load_policy
from iout_mj.agents.rollout import run_episode
from iout_mj.envs import ENV_ID
from iout_mj.errors import UsageError
from iout_mj.experiments.figures import trajectory_figure
from iout_mj.scenarios import ConfigLike, resolve


def use_bundled_ffmpeg() -> None:
    """Point mediapy at imageio-ffmpeg's static binary unless ffmpeg is on the PATH."""
    if shutil.which("ffmpeg") is None:
        mediapy.set_ffmpeg(imageio_ffmpeg.get_ffmpeg_exe())


def non_finite(metrics: dict[str, Any]) -> list[str]:
    """The names of the metrics holding NaN or inf (in lists too)."""
    return [
        key
        for key, value in metrics.items()
        if any(
            isinstance(v, (float, np.floating)) and not math.isfinite(v)
            for v in np.ravel(np.asarray(value, dtype=object))
        )
    ]


def run_mission(
    policy: str = "planner",
    config: ConfigLike = None,
    backend: str = "mujoco",
    seed: int = 0,
    out: Path = Path("renders"),
    video: bool = True,
    width: int = 960,
    height: int = 540,
    fps: int = 30,
    slots: int | None = None,
    name: str = "mission",
    trust_pickle: bool = False,
) -> dict[str, Any]:
    """Fly one mission and write `<name>.json`, `<name>_trajectory.png`, and (with `video`)
    `<name>.mp4` plus its last frame `<name>.png` into `out`. `config` is resolved as for any
    env (`scenarios.resolve`; an `EnvSpec` as it is; None: the paper's N = 2, K = 7). A mission
    whose physics diverged, or with a non-finite metric, has `metrics["valid"] = False` and the
    error in `metrics["error"]`. With the random layout the nodes are drawn from the episode's
    seed."""
    spec = resolve(config, backend=backend)
    cfg = spec.config
    n_auvs, n_nodes = cfg.scenario.n_auvs, cfg.scenario.n_nodes
    if slots is not None and not 1 <= slots <= cfg.scenario.horizon_slots:
        raise UsageError(
            f"slots={slots}: accepted 1 to the mission's {cfg.scenario.horizon_slots} slots"
        )
    out.mkdir(parents=True, exist_ok=True)
    env = gym.make(
        ENV_ID,
        backend=backend,
        config=spec,
        render_mode="rgb_array_list" if video else None,
        width=width,
        height=height,
    )
    act = load_policy(policy, env, seed, trust_pickle)
    writer = None
    bar = tqdm(
        total=slots or cfg.scenario.horizon_slots,
        desc=f"mission {policy} N={n_auvs} K={n_nodes}",
        unit="slot",
    )
    if video:
        use_bundled_ffmpeg()
        writer = mediapy.VideoWriter(out / f"{name}.mp4", shape=(height, width), fps=fps)
        writer.__enter__()
    frames: list[np.ndarray] = []
    count = 0

    def on_step(info: dict[str, Any]) -> None:
        nonlocal frames, count
        bar.update(1)
        if writer is not None:
            frames = env.render()  # type: ignore[assignment]
            for f in frames:
                writer.add_image(f)
            count += len(frames)

    start = time.perf_counter()
    try:
        metrics = run_episode(env, act, seed, on_step, max_steps=slots)
    finally:
        bar.total = bar.n  # an early docking ends the mission before T_max: 100 %
        bar.refresh()
        bar.close()
        if writer is not None:
            writer.__exit__(None, None, None)
    elapsed = time.perf_counter() - start
    bad = non_finite(metrics)
    if bad and "error" not in metrics:
        metrics["error"] = f"non-finite metrics: {', '.join(bad)}"
    metrics["valid"] = "error" not in metrics
    if frames:
        mediapy.write_image(out / f"{name}.png", frames[-1])
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
        "video_frames": count,
        "wall_clock_s": round(elapsed, 2),
    }
    (out / f"{name}.json").write_text(json.dumps(summary, indent=2) + "\n")
    env.close()
    return summary
