"""`iout-mj` command line: link-budget, validate-energy, mission, render, evaluate, figures,
train, bench."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from iout_mj.agents.baselines import POLICIES
from iout_mj.agents.policies import shipped_policies
from iout_mj.config import Config
from iout_mj.envs import BACKENDS
from iout_mj.experiments import bench, bench_report, energy_validation, evaluate, figures
from iout_mj.experiments.mission import run_mission
from iout_mj.scenarios import fixed_config
from iout_mj.schema import ConfigError
from iout_mj.training import TrainConfig, train
from iout_mj.world import acoustics


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a number; accepted a distance > 0 m"
        ) from None
    if not np.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive distance; accepted > 0 m")
    return value


def _load_config(path: str | None) -> Config:
    return Config.load(path) if path else Config()


def cmd_link_budget(args: argparse.Namespace) -> int:
    cfg = _load_config(args.config).acoustics
    d = np.asarray(args.distance, dtype=float)
    rows = [
        {
            "distance_m": float(di),
            "harvest_power_w": float(hp),
            "harvest_energy_j": float(he),
            "uplink_power_w": float(up),
            "uplink_energy_j": float(ue),
        }
        for di, hp, he, up, ue in zip(
            d,
            acoustics.harvest_power_w(d, cfg),
            acoustics.harvest_energy_j(d, cfg),
            acoustics.uplink_power_w(d, cfg),
            acoustics.uplink_energy_j(d, cfg),
            strict=False,
        )
    ]
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    print(
        f"AET at {cfg.f_wet_khz:g} kHz, P_tx {cfg.p_tx_w:g} W; uplink at {cfg.f_data_khz:g} kHz,"
        f" {cfg.data_rate_bps / 1e3:g} kbit/s over {cfg.bandwidth_hz:g} Hz; "
        f"slot {cfg.charging_s:g} s; noise '{cfg.noise_model}'"
    )
    print(
        f"{'distance m':>11} {'harvest W':>11} {'harvest J':>11} {'uplink W':>11} {'uplink J':>11}"
    )
    for r in rows:
        print(
            f"{r['distance_m']:>11.1f} {r['harvest_power_w']:>11.4g} "
            f"{r['harvest_energy_j']:>11.4g} {r['uplink_power_w']:>11.4g} "
            f"{r['uplink_energy_j']:>11.4g}"
        )
    return 0


def cmd_validate_energy(args: argparse.Namespace) -> int:
    cfg = fixed_config(1, 7, _load_config(args.config))
    figure = Path(args.out) / "energy_validation.png"
    result = energy_validation.validate(cfg, figure=figure)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(energy_validation.format_table(result))
        print(f"\nfigure: {figure}")
    return 0


def _run_mission(args: argparse.Namespace, out: Path, name: str, video: bool) -> dict[str, Any]:
    """run_mission with the arguments of `_mission_arguments`, checked."""
    for flag, value, low in (
        ("width", args.width, 16),
        ("height", args.height, 16),
        ("fps", args.fps, 1),
    ):
        if value < low:
            raise ValueError(f"--{flag} {value}: accepted an integer >= {low}")
    return run_mission(
        policy=args.policy,
        n_auvs=args.n_auvs,
        n_nodes=args.nodes,
        backend=args.backend,
        seed=args.seed,
        out=out,
        video=video,
        width=args.width,
        height=args.height,
        fps=args.fps,
        config=args.config,
        slots=args.slots,
        name=name,
    )


def cmd_mission(args: argparse.Namespace) -> int:
    summary = _run_mission(args, Path(args.out), "mission", video=not args.no_video)
    print(json.dumps(summary, indent=2))
    return 0


def cmd_render(args: argparse.Namespace) -> int:
    video = Path(args.out)
    if video.suffix != ".mp4":
        raise ValueError(f"--out {video}: accepted a path ending in .mp4")
    summary = _run_mission(args, video.parent, video.stem, video=True)
    print(f"{video} ({summary['video_frames']} frames), {video.with_suffix('.png')}")
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    rows, episodes = evaluate.evaluate(
        args.policy,
        args.n_auvs,
        args.nodes,
        args.episodes,
        args.seed,
        args.backend,
        workers=args.workers,
    )
    if args.out:
        evaluate.save(rows, episodes, Path(args.out))
    if args.json:
        print(json.dumps(rows, indent=2))
    else:
        print(evaluate.format_table(rows))
        if args.out:
            print(f"\nsaved: {Path(args.out) / 'results.csv'} and results.json")
    return 0


def cmd_figures(args: argparse.Namespace) -> int:
    if not args.results and not args.runs:
        raise ValueError("figures: give --results DIR and/or --runs RUN [RUN ...]")
    out = Path(args.out or args.results or "renders")
    if args.results:
        for path in figures.figures_from_results(Path(args.results), out):
            print(path)
    if args.runs:
        out.mkdir(parents=True, exist_ok=True)
        print(figures.training_curves([Path(r) for r in args.runs], out / "training_curves.png"))
    return 0


def cmd_train(args: argparse.Namespace) -> int:
    cfg = TrainConfig.load(args.config)
    out = Path(args.out or f"runs/{cfg.name}")
    state = train(cfg, out, resume=args.resume)
    print(
        json.dumps(
            {
                "out": str(out),
                "num_timesteps": state.num_timesteps,
                "last_eval": state.history[-1] if state.history else None,
            },
            indent=2,
        )
    )
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    if args.from_json:
        result = json.loads(Path(args.from_json).read_text())
    else:
        result = bench.run_all(quick=args.quick)
    if args.out:
        Path(args.out).write_text(json.dumps(result, indent=2) + "\n")
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(
            bench_report.format_markdown(result)
            if args.markdown
            else bench_report.format_table(result)
        )
    return 0


def _mission_arguments(p: argparse.ArgumentParser, width: int, height: int) -> None:
    p.add_argument(
        "--policy",
        default="planner",
        help=f"{', '.join(POLICIES)}, {', '.join(shipped_policies())} or a policy folder",
    )
    p.add_argument("--n-auvs", type=int, default=2)
    p.add_argument("--nodes", type=int, default=7)
    p.add_argument("--backend", choices=BACKENDS, default="mujoco")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--slots", type=int, default=None, help="stop after this many slots")
    p.add_argument("--width", type=int, default=width)
    p.add_argument("--height", type=int, default=height)
    p.add_argument("--fps", type=int, default=30)
    p.add_argument("--config", help="YAML/JSON config")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="iout-mj", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("link-budget", help="AET harvest and uplink energy vs distance")
    p.add_argument(
        "--distance",
        type=_positive_float,
        nargs="+",
        default=[10, 100, 500],
        help="distances in metres (> 0)",
    )
    p.add_argument("--json", action="store_true")
    p.add_argument("--config", help="YAML/JSON config (default: the paper's values)")
    p.set_defaults(func=cmd_link_budget)

    p = sub.add_parser("validate-energy", help="cubic propulsion model vs MuJoCo actuator power")
    p.add_argument("--json", action="store_true")
    p.add_argument("--out", default="renders", help="folder for the figure")
    p.add_argument("--config", help="YAML/JSON config")
    p.set_defaults(func=cmd_validate_energy)

    p = sub.add_parser("mission", help="run one mission: metrics, trajectory figure, video")
    _mission_arguments(p, width=960, height=540)
    p.add_argument("--out", default="renders", help="folder for mission.{mp4,png,json}")
    p.add_argument("--no-video", action="store_true")
    p.set_defaults(func=cmd_mission)

    p = sub.add_parser("render", help="render a mission to MP4 (headless EGL)")
    _mission_arguments(p, width=1280, height=720)
    p.add_argument("--out", default="renders/mission.mp4", help="the MP4 to write")
    p.set_defaults(func=cmd_render)

    p = sub.add_parser("evaluate", help="seeded episodes per (policy, N, K): mean and std")
    p.add_argument(
        "--policy",
        nargs="+",
        default=["greedy", "round-robin", "random-walk", "planner"],
        help="baseline names, shipped policies (ppo-n1-k7) or policy files",
    )
    p.add_argument("--n-auvs", type=int, nargs="+", default=[1, 2])
    p.add_argument("--nodes", type=int, nargs="+", default=[7])
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--seed", type=int, default=0, help="episode e uses seed S + e")
    p.add_argument("--backend", choices=BACKENDS, default="mujoco")
    p.add_argument("--workers", type=int, default=None, help="processes (default: cores)")
    p.add_argument("--json", action="store_true")
    p.add_argument("--out", help="folder for results.csv / results.json / traces.json")
    p.set_defaults(func=cmd_evaluate)

    p = sub.add_parser("train", help="PPO on a scenario (YAML config); checkpoints, resume")
    p.add_argument("--config", required=True, help="training/configs/<name>.yaml")
    p.add_argument("--out", help="run folder (default runs/<name>)")
    p.add_argument("--resume", action="store_true", help="continue from <out>/last")
    p.set_defaults(func=cmd_train)

    p = sub.add_parser("bench", help="throughput benchmarks (ratios measured in one run)")
    p.add_argument("--json", action="store_true")
    p.add_argument("--quick", action="store_true", help="tiny sizes (a smoke test)")
    p.add_argument("--out", help="also write the JSON here")
    p.add_argument("--markdown", action="store_true", help="the README's table")
    p.add_argument("--from-json", help="format a saved run instead of measuring")
    p.set_defaults(func=cmd_bench)

    p = sub.add_parser("figures", help="the paper's figures from saved evaluation results")
    p.add_argument("--results", help="folder written by evaluate --out")
    p.add_argument("--runs", nargs="+", help="training run folders (training curves)")
    p.add_argument("--out", help="folder for the PNGs (default: the results folder)")
    p.set_defaults(func=cmd_figures)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except (ConfigError, ValueError, FileNotFoundError, FileExistsError) as exc:
        print(f"iout-mj {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
