"""`iout-mj`: the paper's missions on MuJoCo physics, their evaluation and training.

Commands: link-budget, validate-energy, mission, render, evaluate, compare, figures, train,
train-marl, export, sweep, bench, config, list. `--out` is always a folder; `--config` always
an env config (nodes, N, current, noise, reward, physics: `iout-mj config --dump` lists every
key).

Exit codes: 0 done; 1 a bug (the traceback is shown); 2 bad input (the message says what is
accepted); 3 the physics diverged (the mission's metrics are written, marked invalid); 130
interrupted (Ctrl-C).
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence
from typing import Any

# Only light modules here: `iout-mj --help` must not wait for MuJoCo, torch or gymnasium's
# envs. Each command imports what it runs (`commands`); the policy names shown in the help are
# a constant that the tests hold equal to the registry.
from iout_mj.agents.shipped import shipped_policies
from iout_mj.backends.registry import SINGLE_ENV_BACKENDS as BACKENDS
from iout_mj.cli_args import int_at_least, int_between, positive_distance, positive_seconds
from iout_mj.errors import IoutError
from iout_mj.scenarios import LAYOUTS
from iout_mj.vehicles import VEHICLES

BASELINES = (
    "greedy",
    "round-robin",
    "random-walk",
    "planner",
    "comm-first",
    "tour-scheduler",
    "solver-tour",
)
"""The names of `agents.registry.POLICIES`, in its order."""
MAX_FRAME_PX = (1920, 1080)
"""The offscreen framebuffer of the scene (`offwidth`, `offheight` of assets/arena.xml)."""
ERRORS = (IoutError,)
"""Bad input, reported as a message and exit 2; any other exception is a bug (a traceback)."""
INTERRUPTED = 130
"""Exit code after Ctrl-C (128 + SIGINT, as shells report it)."""

LAYOUT_HELP = (
    "paper: the paper's nodes for K = 7 and 13, one seeded layout per K otherwise; random: a new "
    "layout every episode, drawn from the episode's seed (default: the config's own nodes if it "
    "sets scenario.nodes_m, or --nodes-file's, in every episode; else paper)"
)
NODES_FILE_HELP = (
    "CSV of your nodes, one 'x, y' per row in metres (a header row is allowed): flown in every "
    "episode"
)


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows a default only where there is one to show."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if action.default in (None, False, argparse.SUPPRESS) or "(default" in text:
            return text
        return super()._get_help_string(action) or text


def _policy_help() -> str:
    shipped = ", ".join(shipped_policies())
    return (
        f"{', '.join(BASELINES)}, a shipped policy ({shipped}; ppo-general and mappo pick "
        "ppo-general-n<N> and mappo-n<N> for the env's N) or a folder; P+rollout[C] flies a "
        "general policy P with decision-time search, P+dock any policy with the docking shield"
    )


def _config_option(p: argparse.ArgumentParser, what: str) -> None:
    """`--config FILE`, repeatable: several env configs combine in order, a later file's keys
    overriding an earlier one's section by section (`scenarios.combined_mapping`)."""
    p.add_argument(
        "--config",
        action="append",
        metavar="FILE",
        help=f"{what}; repeat to combine files (later ones override earlier ones, section by "
        "section)",
    )


def _trust_pickle(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--trust-pickle",
        action="store_true",
        help="also load legacy SB3 policies (model.zip, vecnormalize.pkl): unpickling runs any "
        "code the files carry, so only for files you trust",
    )


def _mission_arguments(p: argparse.ArgumentParser, width: int, height: int) -> None:
    p.add_argument("--policy", default="planner", help=_policy_help())
    p.add_argument(
        "--n-auvs",
        type=int_at_least(1),
        default=None,
        help="AUVs N, 1 to 4 (default: the config file's, else 2)",
    )
    p.add_argument(
        "--n-nodes",
        "--nodes",
        dest="nodes",
        type=int_at_least(2),
        default=None,
        help="sensor nodes K, 2 to 30: the paper's layout for 7 and 13, else one seeded layout "
        "per K (default: the config file's, else 7)",
    )
    p.add_argument("--backend", choices=BACKENDS, default="mujoco", help="how vehicles move")
    p.add_argument("--seed", type=int_at_least(0), default=0, help="episode seed (>= 0)")
    p.add_argument(
        "--slots",
        type=int_at_least(1),
        default=None,
        help="stop early after this many slots (the mission and its horizon stay as they are; "
        "metrics are those of the slots flown; default: fly to the end)",
    )
    frame = "the offscreen framebuffer of the scene"
    p.add_argument(
        "--width",
        type=int_between(16, MAX_FRAME_PX[0], frame),
        default=width,
        help=f"frame width, pixels (16 to {MAX_FRAME_PX[0]})",
    )
    p.add_argument(
        "--height",
        type=int_between(16, MAX_FRAME_PX[1], frame),
        default=height,
        help=f"frame height, pixels (16 to {MAX_FRAME_PX[1]})",
    )
    p.add_argument(
        "--fps",
        type=int_between(1, 240, "a video player's rates"),
        default=30,
        help="video frames per second (1 to 240)",
    )
    p.add_argument("--layout", choices=LAYOUTS, default=None, help=LAYOUT_HELP)
    p.add_argument("--nodes-file", help=NODES_FILE_HELP)
    _config_option(
        p,
        "YAML/JSON env config (nodes, N, current, noise, reward, physics...); a flag that "
        "contradicts what it sets is an error",
    )
    _trust_pickle(p)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="iout-mj", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    parser.add_argument(
        "--quiet", action="store_true", help="no progress bars (errors and results still print)"
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    fmt: dict[str, Any] = {"formatter_class": _HelpFormatter}

    p = sub.add_parser("link-budget", help="AET harvest and uplink energy vs distance", **fmt)
    p.add_argument(
        "--distance",
        type=positive_distance,
        nargs="+",
        default=[10, 100, 500],
        help="AUV-node distances, metres (> 0)",
    )
    p.add_argument("--json", action="store_true", help="print JSON rows instead of a table")
    _config_option(
        p,
        "YAML/JSON config (default: the paper's values); with "
        "channel.transmission_loss_file the table's TL at each horizontal distance and AUV depth",
    )
    p.set_defaults(func="cmd_link_budget")

    p = sub.add_parser(
        "tl-table",
        help="site-specific transmission-loss table by BELLHOP (needs the bellhop extra)",
        description="Compute a transmission-loss table over horizontal range and AUV depth for "
        "a node on the config's seabed (channel.node_depth_m), at the config's AET and data "
        "frequencies, in a Mackenzie sound-speed profile of its channel temperature and "
        "salinity (or --profile), by BELLHOP through the optional package pelagic "
        "(`pip install -e .[bellhop]`); set the file as channel.transmission_loss_file.",
        **fmt,
    )
    _config_option(p, "YAML/JSON config (default: the paper's values)")
    p.add_argument(
        "--profile", help="sound-speed profile CSV, 'depth_m, c_mps' rows from 0 m to the seabed"
    )
    p.add_argument(
        "--max-range-m",
        type=positive_distance,
        help="last horizontal range, metres (default: the area's diagonal, rounded up to a step)",
    )
    p.add_argument(
        "--range-step-m",
        type=positive_distance,
        default=10.0,
        help="spacing of the horizontal ranges, metres",
    )
    p.add_argument(
        "--depth-points",
        type=int_between(2, 128, "the compiled link constants hold 128 depths"),
        default=21,
        help="AUV depths from 1 m to the source, evenly spaced",
    )
    p.add_argument("--out", required=True, help="the table file to write (.npz)")
    p.set_defaults(func="cmd_tl_table")

    p = sub.add_parser(
        "validate-energy", help="cubic propulsion model vs MuJoCo actuator power", **fmt
    )
    p.add_argument("--json", action="store_true", help="print JSON instead of tables")
    p.add_argument("--out", default="renders", help="folder for energy_validation.png")
    _config_option(p, "YAML/JSON config (default: the paper's values)")
    p.add_argument(
        "--vehicle",
        choices=sorted(VEHICLES),
        help="the hull (default: the config's physics.vehicle); remus100 adds the checks "
        "against published data and the paper's C_d S",
    )
    p.set_defaults(func="cmd_validate_energy")

    p = sub.add_parser("mission", help="one mission: metrics, trajectory figure, video", **fmt)
    _mission_arguments(p, width=960, height=540)
    p.add_argument("--out", default="renders", help="folder for mission.{mp4,png,json}")
    p.add_argument("--no-video", action="store_true", help="metrics and figure only (faster)")
    p.add_argument(
        "--trace",
        help="write a per-slot trace to FILE.csv (one row per slot and link) and FILE.json "
        "(nested per slot): positions, depths, transmissions, SINR, PER, packets, bits, AoI",
        metavar="FILE",
    )
    p.set_defaults(func="cmd_mission")

    p = sub.add_parser("render", help="a mission to MP4 (headless EGL)", **fmt)
    _mission_arguments(p, width=1280, height=720)
    p.add_argument("--out", default="renders", help="folder for mission.{mp4,png,json}")
    p.set_defaults(func="cmd_render")

    p = sub.add_parser("evaluate", help="seeded episodes per (policy, N, K): mean and std", **fmt)
    p.add_argument(
        "--policy",
        nargs="+",
        default=list(BASELINES),
        help=_policy_help() + "; cells a trained policy cannot serve are skipped",
    )
    p.add_argument(
        "--n-auvs",
        type=int_at_least(1),
        nargs="+",
        default=None,
        help="AUVs N (default: the config's N if it sets one, else 1 2)",
    )
    p.add_argument(
        "--n-nodes",
        "--nodes",
        dest="nodes",
        type=int_at_least(2),
        nargs="+",
        default=None,
        help="nodes K: the paper's layout for 7 and 13, else one seeded layout per K (default: "
        "the config's or --nodes-file's own nodes, else 7)",
    )
    p.add_argument("--nodes-file", help=NODES_FILE_HELP)
    p.add_argument("--episodes", type=int_at_least(1), default=20, help="episodes per cell")
    p.add_argument("--seed", type=int_at_least(0), default=0, help="episode e uses seed S + e")
    p.add_argument(
        "--training-seeds",
        type=int_at_least(0),
        nargs="+",
        default=[0],
        metavar="SEED",
        help="training seeds each learned policy P is flown as: 0 is P itself, k >= 1 the policy "
        "P-seed<k> resolved like P (ppo-general-n<N>-seed<k>, or the folder P-seed<k>); "
        "baselines are flown once; the rows keep the name P and say training_seed",
    )
    p.add_argument("--backend", choices=BACKENDS, default="mujoco", help="how vehicles move")
    p.add_argument(
        "--workers",
        type=int_at_least(1),
        default=None,
        help="processes, at most one per CPU (default: one per CPU)",
    )
    p.add_argument("--layout", choices=LAYOUTS, default=None, help=LAYOUT_HELP)
    _config_option(
        p,
        "YAML/JSON env config (current, noise, reward, physics, and your own nodes or N, "
        "kept in every episode); a flag that contradicts what it sets is an error",
    )
    p.add_argument("--json", action="store_true", help="print JSON rows instead of a table")
    p.add_argument("--out", help="folder for results.csv / results.json / traces.json")
    p.add_argument(
        "--ray",
        nargs="?",
        const="local",
        default=None,
        metavar="ADDRESS",
        help="run the episodes as Ray tasks: a local instance, or the cluster at ADDRESS",
    )
    _ray_timeout(p)
    _trust_pickle(p)
    p.set_defaults(func="cmd_evaluate")

    p = sub.add_parser(
        "sweep", help="Ray Tune trials over scenarios x seeds x hyperparameters", **fmt
    )
    p.add_argument(
        "sweep_config",
        help="sweep YAML: base, grid, cpus_per_trial, metric, mode (see "
        "training/configs/sweep-smoke.yaml)",
    )
    p.add_argument("--out", default="runs/sweep", help="folder for the trials, results, best.yaml")
    p.add_argument(
        "--ray",
        nargs="?",
        const="local",
        default="local",
        metavar="ADDRESS",
        help="a local Ray instance, or the cluster at ADDRESS",
    )
    _ray_timeout(p)
    p.set_defaults(func="cmd_sweep")

    p = sub.add_parser("train", help="PPO on a scenario (YAML config); checkpoints, resume", **fmt)
    p.add_argument("train_config", help="the training config, training/configs/<name>.yaml")
    _config_option(
        p,
        "YAML/JSON env config instead of the training config's env: (nodes, current, "
        "noise, reward, ...)",
    )
    p.add_argument("--out", help="run folder (default: runs/<name>, runs/<name>-seed<S>)")
    p.add_argument("--resume", action="store_true", help="continue the run in <out>")
    p.add_argument(
        "--overwrite", action="store_true", help="replace the run already in <out> (not resumed)"
    )
    p.add_argument(
        "--seed",
        type=int_at_least(0),
        help="training seed instead of the config's (default run folder runs/<name>-seed<S>)",
    )
    p.add_argument("--layout", choices=LAYOUTS, help="node layout instead of the config's")
    p.add_argument("--n-auvs", type=int_at_least(1), help="AUVs N instead of the config's")
    p.add_argument(
        "--n-nodes",
        "--nodes",
        dest="nodes",
        type=int_at_least(2),
        help="nodes K instead of the config's",
    )
    p.add_argument("--nodes-file", help=NODES_FILE_HELP + ", instead of the config's nodes")
    p.add_argument(
        "--steps",
        type=int_at_least(1),
        help="total PPO steps instead of the config's (its phases scaled to them)",
    )
    p.add_argument(
        "--torch-threads",
        type=int_at_least(1),
        help="torch threads instead of the config's: 1 to train two runs side by side on two "
        "cores (README \"Performance\"); floats may round otherwise than with the config's",
    )
    p.set_defaults(func="cmd_train")

    p = sub.add_parser(
        "train-marl",
        help="MAPPO or IPPO on the PettingZoo env (TorchRL; pip install -e '.[mappo]')",
        **fmt,
    )
    p.add_argument("marl_config", help="the config, training/configs/mappo-*.yaml or ippo-*.yaml")
    p.add_argument("--out", help="run folder (default: runs/<name>, runs/<name>-seed<S>)")
    p.add_argument("--resume", action="store_true", help="continue the run in <out>")
    p.add_argument(
        "--seed",
        type=int_at_least(0),
        help="training seed instead of the config's (default run folder runs/<name>-seed<S>)",
    )
    p.add_argument(
        "--steps",
        type=int_at_least(1),
        help="total agent steps instead of the config's (its phases scaled to them)",
    )
    p.add_argument("--quiet", action="store_true", help="no evaluation rows while training")
    p.set_defaults(func="cmd_train_marl")

    p = sub.add_parser(
        "compare",
        help="a policy against a reference in every cell of an evaluation: IQM AoI with 95 %% "
        "stratified-bootstrap CIs, probability of improvement (rliable)",
        **fmt,
    )
    p.add_argument(
        "--results",
        required=True,
        nargs="+",
        help="folders from evaluate --out (several: policies evaluated apart, read together, "
        "and a learned policy's training seeds evaluated apart pooled; with --grid each folder "
        "is a condition)",
    )
    p.add_argument(
        "--policy",
        required=True,
        nargs="+",
        help="the policy's name in the results (several with --grid)",
    )
    p.add_argument(
        "--reference",
        default="tour-scheduler",
        help="the policy to compare with, or best-planner: in every cell, the baseline with the "
        "lowest mean AoI(Tmax) that the results hold",
    )
    p.add_argument(
        "--bootstrap-reps",
        type=int_at_least(100),
        default=2000,
        help="stratified-bootstrap resamples of every 95 %% confidence interval",
    )
    p.add_argument(
        "--bootstrap-seed",
        type=int_at_least(0),
        default=0,
        help="seed of the bootstrap's resampling (default: 0)",
    )
    p.add_argument(
        "--grid",
        action="store_true",
        help="each --results folder a condition (noise, currents) over the same cells: one "
        "table of the cells by condition, every --policy's IQM ratio in each",
    )
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.set_defaults(func="cmd_compare")

    p = sub.add_parser(
        "export", help="a training checkpoint as a policy folder to ship or share", **fmt
    )
    p.add_argument("checkpoint", help="a run's best/ or last/ folder")
    p.add_argument("--out", required=True, help="the policy folder to write (replaced whole)")
    p.set_defaults(func="cmd_export")

    p = sub.add_parser("bench", help="throughput benchmarks (ratios measured in one run)", **fmt)
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.add_argument("--quick", action="store_true", help="tiny sizes (a smoke test)")
    p.add_argument("--out", help="also write the run as bench.json (bench-warp.json) here")
    p.add_argument("--markdown", action="store_true", help="the README's table")
    p.add_argument("--from-json", help="format a saved run instead of measuring")
    p.add_argument(
        "--warp",
        action="store_true",
        help="only the warp backend's benchmark (MuJoCo Warp on the GPU it finds, else CPU)",
    )
    p.add_argument(
        "--warp-sizes",
        type=int_at_least(1),
        nargs="+",
        help="batch sizes B of --warp (default: 256 1024 4096 16384 on a GPU, 4 16 on a CPU)",
    )
    p.set_defaults(func="cmd_bench")

    p = sub.add_parser("figures", help="the paper's figures from saved results", **fmt)
    p.add_argument(
        "--results",
        nargs="+",
        help="folders written by evaluate --out (several: read together, each policy's cell once)",
    )
    p.add_argument(
        "--policies", nargs="+", metavar="POLICY", help="draw only these (default: every one)"
    )
    p.add_argument(
        "--label",
        nargs="+",
        default=[],
        metavar="POLICY=NAME",
        help="a policy's name in the legend (one NAME may gather one policy per N)",
    )
    p.add_argument("--runs", nargs="+", help="training run folders (training curves)")
    p.add_argument("--out", help="folder for the PNGs (default: the results folder)")
    p.set_defaults(func="cmd_figures")

    p = sub.add_parser("config", help="the env config: every key, default, unit and range", **fmt)
    _config_option(p, "a YAML/JSON env config to show whole (default: the paper's values)")
    p.add_argument(
        "--markdown", action="store_true", help="the reference as Markdown (docs/config.md)"
    )
    p.add_argument(
        "--dump", action="store_true", help="commented YAML, a file to start from (the default)"
    )
    p.set_defaults(func="cmd_config")

    p = sub.add_parser("list", help="scenarios, policies, backends, layouts and vehicles", **fmt)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func="cmd_list")
    return parser


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("iout-mj")
    except PackageNotFoundError:  # a source tree that was never installed
        return "unknown"


def _ray_timeout(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--ray-timeout",
        type=positive_seconds,
        default=30.0,
        metavar="SECONDS",
        help="how long to wait for the Ray cluster at ADDRESS to answer",
    )


def _interrupted(exc: BaseException | None) -> bool:
    """Whether `exc` is Ctrl-C, or an error raised while handling it (a child process that the
    same Ctrl-C ended, such as the video encoder)."""
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__context__
    return False


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    before = os.environ.get("TQDM_DISABLE")
    if args.quiet:
        os.environ["TQDM_DISABLE"] = "1"  # every progress bar of the project is tqdm's
    try:
        from iout_mj import commands  # the layers each command runs import when it runs

        return int(getattr(commands, args.func)(args))
    except BaseException as exc:
        if _interrupted(exc):
            sys.unraisablehook = lambda _: None  # what Ctrl-C left half-closed stays quiet
            print(f"iout-mj {args.command}: interrupted", file=sys.stderr)
            return INTERRUPTED
        if isinstance(exc, ERRORS):
            print(f"iout-mj {args.command}: error: {exc}", file=sys.stderr)
            return 2
        raise
    finally:  # a caller of main() in its own process keeps its environment
        if before is None:
            os.environ.pop("TQDM_DISABLE", None)
        else:
            os.environ["TQDM_DISABLE"] = before


if __name__ == "__main__":
    sys.exit(main())
