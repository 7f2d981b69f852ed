"""One mission end to end: a policy flies it, metrics and figures are saved, a video is written."""

from __future__ import annotations

import csv
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


TRACE_COLUMNS = (
    "slot",
    "auv",
    "auv_x_m",
    "auv_y_m",
    "auv_depth_m",
    "active",
    "docked",
    "aet_node",
    "uplink_node",
    "node_x_m",
    "node_y_m",
    "node_depth_m",
    "node_energy_j",
    "range_m",
    "uplink_ok",
    "sinr_db",
    "per",
    "packets_sent",
    "packets_received",
    "bits_delivered",
    "node_aoi",
    "mean_aoi",
)
"""The columns of a mission trace's CSV, one row per slot and link (AUV i's uplink):

- slot: 1 to T, the slot just flown; auv: i.
- auv_x_m, auv_y_m, auv_depth_m: AUV i at the end of the slot (where its links were
  budgeted); depth 0 with the channel's depth off (the paper's plane).
- active: not docked at the start of the slot (only active AUVs charge and collect);
  docked: at its end.
- aet_node, uplink_node: the nodes AUV i charges (AET) and collects from (the action).
- node_x_m, node_y_m, node_depth_m, node_energy_j: that uplink node, its energy stored after
  the slot (harvest in, uplink cost out).
- range_m: AUV i to its uplink node (slant with depth on).
- uplink_ok: the node's update reached the network and AUV i named it.
- sinr_db, per: the uplink's SINR at AUV i and its packet error rate (empty: the paper's
  channel, or no transmission reached AUV i); packets_sent by the node, packets_received at
  any AUV (0 on the paper's channel).
- bits_delivered: the node's bits that arrived this slot, on the row of the first active AUV
  naming it (0 on the others): the column sums to the mission's delivered bits.
- node_aoi: the uplink node's AoI after the slot; mean_aoi: over all nodes.

The JSON trace holds the same per slot, nested: {"slot", "auvs": [...], "nodes": [...]},
every node's position, depth, energy, AoI and bits with its slot, for a network simulator to
replay (positions, depths and the transmissions with their outcomes)."""


class MissionTracer:
    """Records one env's mission after every slot (`record`), then writes the trace as CSV
    (`TRACE_COLUMNS`) and JSON."""

    def __init__(self, env: Any):
        self.mission = env.unwrapped.mission
        self.slots: list[dict[str, Any]] = []
        self._bits = np.zeros(self.mission.n_nodes)  # a reset's: no bits, no AUV docked
        self._docked = np.zeros(self.mission.n_auvs, dtype=bool)

    def record(self, info: dict[str, Any]) -> None:
        """The slot just flown (call after each step, with its info)."""
        m, net, s = self.mission, self.mission.network, self.mission.state
        slot = int(s.slot)
        links = info.get("channel") or {}
        delta = net.node_bits - self._bits
        credited: set[int] = set()
        auvs = []
        for i in range(m.n_auvs):
            aet, up = (int(v) for v in s.action[i, 2:4])
            active = not bool(self._docked[i])
            first = active and up not in credited
            credited |= {up} if active else set()
            auvs.append(
                {
                    "auv": i,
                    "position_m": s.positions_m[i].tolist(),
                    "depth_m": float(m.auv_depth_m[i]),
                    "active": active,
                    "docked": bool(s.docked[i]),
                    "aet_node": aet,
                    "uplink_node": up,
                    "range_m": float(s.distance_m[i, up]),
                    "uplink_ok": bool(m.log.uplink_ok[slot - 1, i]),
                    "sinr_db": _finite(links.get("sinr_db"), i),
                    "per": _finite(links.get("per"), i),
                    "packets_sent": int(links["packets_sent"][i]) if links else 0,
                    "packets_received": int(links["packets_received"][i]) if links else 0,
                    "bits_delivered": float(delta[up]) if first else 0.0,
                }
            )
        nodes = [
            {
                "node": j,
                "position_m": net.nodes_m[j].tolist(),
                "depth_m": float(m.node_depth_m[j]),
                "energy_j": float(net.energy_j[j]),
                "aoi": float(net.aoi[j]),
                "bits_delivered": float(delta[j]),
            }
            for j in range(m.n_nodes)
        ]
        self.slots.append(
            {"slot": slot, "mean_aoi": float(net.mean_aoi), "auvs": auvs, "nodes": nodes}
        )
        self._bits = net.node_bits.copy()
        self._docked = s.docked.copy()

    def rows(self) -> list[dict[str, Any]]:
        """The CSV's rows (`TRACE_COLUMNS`), one per slot and AUV."""
        out = []
        for slot in self.slots:
            for a in slot["auvs"]:
                node = slot["nodes"][a["uplink_node"]]
                out.append(
                    {
                        "slot": slot["slot"],
                        "auv": a["auv"],
                        "auv_x_m": a["position_m"][0],
                        "auv_y_m": a["position_m"][1],
                        "auv_depth_m": a["depth_m"],
                        "active": int(a["active"]),
                        "docked": int(a["docked"]),
                        "aet_node": a["aet_node"],
                        "uplink_node": a["uplink_node"],
                        "node_x_m": node["position_m"][0],
                        "node_y_m": node["position_m"][1],
                        "node_depth_m": node["depth_m"],
                        "node_energy_j": node["energy_j"],
                        "range_m": a["range_m"],
                        "uplink_ok": int(a["uplink_ok"]),
                        "sinr_db": "" if a["sinr_db"] is None else a["sinr_db"],
                        "per": "" if a["per"] is None else a["per"],
                        "packets_sent": a["packets_sent"],
                        "packets_received": a["packets_received"],
                        "bits_delivered": a["bits_delivered"],
                        "node_aoi": node["aoi"],
                        "mean_aoi": slot["mean_aoi"],
                    }
                )
        return out

    def write(self, path: Path) -> tuple[Path, Path]:
        """`path` with suffix .csv and .json (the suffix given, if any, is replaced)."""
        csv_path, json_path = path.with_suffix(".csv"), path.with_suffix(".json")
        with csv_path.open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=TRACE_COLUMNS)
            writer.writeheader()
            writer.writerows(self.rows())
        json_path.write_text(json.dumps({"slots": self.slots}, indent=1) + "\n")
        return csv_path, json_path


def _finite(values: Any, i: int) -> float | None:
    """values[i] as a number, None where absent or NaN (no transmission reached the AUV)."""
    if not values or not math.isfinite(values[i]):
        return None
    return float(values[i])


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
    trace_path: Path | None = None,
) -> dict[str, Any]:
    """Fly one mission and write `<name>.json`, `<name>_trajectory.png`, and (with `video`)
    `<name>.mp4` plus its last frame `<name>.png` into `out`. `config` is resolved as for any
    env (`scenarios.resolve`; an `EnvSpec` as it is; None: the paper's N = 2, K = 7). A mission
    whose physics diverged, or with a non-finite metric, has `metrics["valid"] = False` and the
    error in `metrics["error"]`. With the random layout the nodes are drawn from the episode's
    seed. With `trace_path`, the per-slot trace is written there as .csv and .json
    (`TRACE_COLUMNS`)."""
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
    tracer = MissionTracer(env) if trace_path is not None else None

    def on_step(info: dict[str, Any]) -> None:
        nonlocal frames, count
        bar.update(1)
        if tracer is not None:
            tracer.record(info)
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
    if tracer is not None and trace_path is not None:
        tracer.write(trace_path)
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
