"""The commands of `iout-mj`, one function each (the parser is in `cli`, which imports this
module only once the arguments are parsed).

Each command imports the layers it runs when it runs: torch and stable-baselines3 take about
2 s to import, and `iout-mj link-budget` should not wait for them. A command that writes into
an output folder holds that folder alone while it runs (`runtime.output_lock`): a second run
into it is refused at once.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from iout_mj.cli_args import writable_dir
from iout_mj.errors import UsageError
from iout_mj.files import write_atomic
from iout_mj.runtime import output_lock
from iout_mj.scenarios import fixed_config, load_config, resolve
from iout_mj.world import acoustics

DIVERGED = 3
"""Exit code of a mission whose physics diverged (its metrics are written, marked invalid)."""


def cmd_link_budget(args: argparse.Namespace) -> int:
    env = load_config(args.config)
    cfg, channel = env.acoustics, env.channel
    d = np.asarray(args.distance, dtype=float)
    table = channel.transmission_loss_file
    rows = _formula_rows(cfg, channel, d) if table is None else _table_rows(env, d)
    links = _channel_links(env, d) if channel.features else None
    if args.json:
        print(json.dumps(rows if links is None else {"link": rows, "channel": links}, indent=2))
        return 0
    print(
        f"AET at {cfg.f_wet_khz:g} kHz, P_tx {cfg.p_tx_w:g} W; uplink at {cfg.f_data_khz:g} kHz,"
        f" {cfg.data_rate_bps / 1e3:g} kbit/s over {cfg.bandwidth_hz:g} Hz; "
        f"slot {cfg.charging_s:g} s; noise '{cfg.noise_model}'"
        + ("" if channel.absorption == "thorp" else f"; absorption '{channel.absorption}'")
        + ("" if table is None else f"; TL from the table {Path(table).name} (horizontal range)")
    )
    columns = BUDGET_COLUMNS if table is None else TABLE_COLUMNS
    print(" ".join(f"{title.format(ac=cfg):>11}" for _, title, _ in columns))
    for r in rows:
        print(" ".join(f"{r[key]:>11{fmt}}" for key, _, fmt in columns))
    if links is not None:
        _print_channel_links(channel, links)
    return 0


BUDGET_COLUMNS = (
    ("distance_m", "distance m", ".1f"),
    ("harvest_power_w", "harvest W", ".4g"),
    ("harvest_energy_j", "harvest J", ".4g"),
    ("uplink_power_w", "uplink W", ".4g"),
    ("uplink_energy_j", "uplink J", ".4g"),
)
"""The link table of `iout-mj link-budget`: key, heading, format."""
TABLE_COLUMNS = (
    BUDGET_COLUMNS[0],
    ("auv_depth_m", "AUV z m", ".1f"),
    ("tl_wet_db", "TL {ac.f_wet_khz:g} kHz", ".2f"),
    ("tl_data_db", "TL {ac.f_data_khz:g} kHz", ".2f"),
    *BUDGET_COLUMNS[1:],
)
"""The same with a transmission-loss table: the AUV's depth and the table's TL columns."""


def _formula_rows(cfg: Any, channel: Any, d: np.ndarray) -> list[dict[str, float]]:
    """The link budget at each distance: spreading and absorption (`world.acoustics`)."""
    return [
        {
            "distance_m": float(di),
            "harvest_power_w": float(hp),
            "harvest_energy_j": float(he),
            "uplink_power_w": float(up),
            "uplink_energy_j": float(ue),
        }
        for di, hp, he, up, ue in zip(
            d,
            acoustics.harvest_power_w(d, cfg, channel),
            acoustics.harvest_energy_j(d, cfg, channel),
            acoustics.uplink_power_w(d, cfg, channel),
            acoustics.uplink_energy_j(d, cfg, channel),
            strict=True,
        )
    ]


def _table_rows(env: Any, d: np.ndarray) -> list[dict[str, float]]:
    """The compiled link budget with the channel's transmission-loss table at each horizontal
    range and each distinct AUV depth of the config."""
    cfg, channel = env.acoustics, env.channel
    link = acoustics.LinkBudget(cfg, channel)
    auv_m, node_m = channel.depths_m(env.scenario.n_auvs, env.scenario.n_nodes)
    rows = []
    for h in d:
        for a in sorted(set(auv_m)):
            (harvest,), (uplink,) = link.energies_j([h], a, node_m[0])
            (wet,), (data,) = link.transmission_loss_db([h], a, node_m[0])
            rows.append(
                {
                    "distance_m": float(h),
                    "auv_depth_m": a,
                    "tl_wet_db": float(wet),
                    "tl_data_db": float(data),
                    "harvest_power_w": float(harvest) / cfg.charging_s,
                    "harvest_energy_j": float(harvest),
                    "uplink_power_w": float(uplink) / cfg.data_s,
                    "uplink_energy_j": float(uplink),
                }
            )
    return rows


def cmd_tl_table(args: argparse.Namespace) -> int:
    from iout_mj.world import tl_table  # the compiled link budget, and pelagic when it runs

    env = load_config(args.config)
    if args.max_range_m is None:  # the area's diagonal, rounded up to a whole step
        diagonal_m = float(np.hypot(*env.scenario.area_m))
        max_range_m = args.range_step_m * np.ceil(diagonal_m / args.range_step_m)
    else:
        max_range_m = args.max_range_m
    out = Path(args.out)
    if out.suffix != ".npz":
        raise UsageError(f"--out {out}: accepted a file name ending in .npz")
    writable_dir(out.parent)
    frequencies = (env.acoustics.f_wet_khz, env.acoustics.f_data_khz)
    print(
        f"tl-table: BELLHOP at {frequencies[0]:g} and {frequencies[1]:g} kHz to "
        f"{max_range_m:g} m every {args.range_step_m:g} m, seabed {env.channel.node_depth_m:g} m",
        file=sys.stderr,
    )
    table = tl_table.compute_table(
        env.channel,
        frequencies,
        max_range_m=float(max_range_m),
        range_step_m=args.range_step_m,
        depth_points=args.depth_points,
        profile_csv=None if args.profile is None else Path(args.profile),
    )
    tl_table.check_link_table(table, env.acoustics, env.channel)
    tl_table.save_table(table, out)
    print(
        f"{out}: {table.frequency_khz.size} frequencies x {table.depth_m.size} depths "
        f"({table.depth_m[0]:g} to {table.depth_m[-1]:g} m) x {table.range_m.size} ranges "
        f"({table.range_m[0]:g} to {table.range_m[-1]:g} m), source at "
        f"{table.source_depth_m:g} m; use it as channel.transmission_loss_file"
    )
    return 0


LINK_COLUMNS = (
    ("horizontal_m", "horiz m", ".1f"),
    ("auv_depth_m", "AUV z m", ".1f"),
    ("node_depth_m", "node z m", ".1f"),
    ("range_m", "range m", ".1f"),
    ("sound_speed_mps", "c m/s", ".1f"),
    ("delay_s", "delay s", ".4f"),
    ("usable_share", "usable", ".3f"),
    ("uplink_cost_j", "cost J", ".4g"),
    ("snr_db", "SNR dB", ".2f"),
    ("per", "PER", ".3g"),
    ("packets_sent", "sent", ".0f"),
    ("packets_expected", "expected", ".1f"),
)
"""The channel table of `iout-mj link-budget`: key, heading, format."""


def _channel_links(env: Any, horizontal_m: np.ndarray) -> list[dict[str, float]]:
    """The channel's link budget at each horizontal range for every distinct pair of an AUV
    depth and a node depth of the config (`acoustics.channel_link_budget`)."""
    auv_m, node_m = env.channel.depths_m(env.scenario.n_auvs, env.scenario.n_nodes)
    pairs = sorted({(a, z) for a in auv_m for z in node_m})  # (0, 0) with depth off
    return [
        acoustics.channel_link_budget(env.channel, env.acoustics, float(h), a, z)
        for h in horizontal_m
        for a, z in pairs
    ]


def _print_channel_links(channel: Any, links: list[dict[str, float]]) -> None:
    print(
        f"\nchannel: {', '.join(channel.features)}; one uplink alone in its slot, no fading "
        "(usable: share of tau_data left by the handshake; cost: E_req x usable; SNR = SINR "
        "without interference; expected: packets sent x (1 - PER))"
    )
    print(" ".join(f"{title:>9}" for _, title, _ in LINK_COLUMNS))
    for r in links:
        print(" ".join(f"{r[key]:>9{fmt}}" for key, _, fmt in LINK_COLUMNS))


def cmd_validate_energy(args: argparse.Namespace) -> int:
    from iout_mj.experiments import energy_validation  # heavy: see the module docstring

    cfg = fixed_config(1, 7, load_config(args.config))
    if args.vehicle is not None:
        cfg = cfg.with_vehicle(args.vehicle)
    out = writable_dir(Path(args.out))
    figure = out / "energy_validation.png"
    print("validate-energy: steady state, manoeuvres, timestep test (about 5 s)", file=sys.stderr)
    with output_lock(out, "validate-energy"):
        result = energy_validation.validate_vehicle(cfg, figure=figure)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(energy_validation.format_vehicle_table(result))
        print(f"\nfigure: {figure}")
    return 0


def _run_mission(args: argparse.Namespace, out: Path, name: str, video: bool) -> dict[str, Any]:
    from iout_mj.experiments.mission import run_mission  # heavy: see the module docstring

    spec = resolve(
        args.config, args.n_auvs, args.nodes, args.layout, args.backend, args.nodes_file, flags=True
    )
    horizon = spec.config.scenario.horizon_slots
    if args.slots is not None and args.slots > horizon:
        raise UsageError(
            f"--slots {args.slots} is more than the mission's {horizon} slots: accepted 1 to "
            f"{horizon} (stop early), or set scenario.horizon_slots in --config"
        )
    with output_lock(writable_dir(out), args.command):
        return run_mission(
            policy=args.policy,
            config=spec,
            backend=args.backend,
            seed=args.seed,
            out=out,
            video=video,
            width=args.width,
            height=args.height,
            fps=args.fps,
            slots=args.slots,
            name=name,
            trust_pickle=args.trust_pickle,
            trace_path=Path(args.trace) if getattr(args, "trace", None) else None,
        )


def _diverged(summary: dict[str, Any], command: str) -> int:
    if summary["metrics"]["valid"]:
        return 0
    print(f"iout-mj {command}: error: {summary['metrics']['error']}", file=sys.stderr)
    return DIVERGED


def cmd_mission(args: argparse.Namespace) -> int:
    summary = _run_mission(args, Path(args.out), "mission", video=not args.no_video)
    print(json.dumps(summary, indent=2))
    return _diverged(summary, "mission")


def cmd_render(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.suffix == ".mp4":
        raise UsageError(f"--out {out}: accepted a folder (render writes mission.mp4 into it)")
    summary = _run_mission(args, out, "mission", video=True)
    print(f"{out / 'mission.mp4'} ({summary['video_frames']} frames), {out / 'mission.png'}")
    return _diverged(summary, "render")


def cmd_evaluate(args: argparse.Namespace) -> int:
    out = writable_dir(Path(args.out)) if args.out else None
    if out is None:
        return _evaluate(args, None)
    with output_lock(out, "evaluate"):
        return _evaluate(args, out)


def _evaluate(args: argparse.Namespace, out: Path | None) -> int:
    from iout_mj.experiments import evaluate  # heavy: see the module docstring

    skipped: list[str] = []
    rows, episodes = evaluate.evaluate(
        args.policy,
        args.n_auvs,
        args.nodes,
        args.episodes,
        args.seed,
        args.backend,
        workers=args.workers,
        trust_pickle=args.trust_pickle,
        skipped=skipped,
        layout=args.layout,
        base=args.config,
        ray_address=args.ray,
        ray_timeout_s=args.ray_timeout,
        nodes_file=args.nodes_file,
        training_seeds=args.training_seeds,
    )
    for note in skipped:
        print(note, file=sys.stderr)
    if out:
        evaluate.save(rows, episodes, out)
    if args.json:
        print(json.dumps(rows, indent=2))
    else:
        print(evaluate.format_table(rows))
        if out:
            print(f"\nsaved: {out / 'results.csv'} and results.json")
    return 0


def cmd_figures(args: argparse.Namespace) -> int:
    from iout_mj.experiments import figures  # matplotlib: see the module docstring

    if not args.results and not args.runs:
        raise UsageError("figures: give --results DIR and/or --runs RUN [RUN ...]")
    labels = {}
    for item in args.label:
        policy, sep, name = item.rpartition("=")
        if not sep or not policy or not name:
            raise UsageError(f"figures --label {item!r}: accepted POLICY=NAME")
        labels[policy] = name
    if (labels or args.policies) and not args.results:
        raise UsageError("figures: --label and --policies need --results DIR [DIR ...]")
    out = writable_dir(Path(args.out or (args.results or ["renders"])[0]))
    with output_lock(out, "figures"):
        if args.results:
            skipped: list[str] = []
            folders = [Path(r) for r in args.results]
            for path in figures.figures_from_results(folders, out, skipped, labels, args.policies):
                print(path)
            for note in skipped:
                print(note, file=sys.stderr)
        if args.runs:
            runs = [Path(r) for r in args.runs]
            print(figures.training_curves(runs, out / "training_curves.png"))
    return 0


def cmd_train(args: argparse.Namespace) -> int:
    from iout_mj.training import TrainConfig, train  # heavy: see the module docstring
    from iout_mj.training.trainer import run_summary

    cfg = TrainConfig.load(args.train_config)
    name = cfg.name
    if args.seed is not None:
        name = f"{cfg.name}-seed{args.seed}"
    cfg = train_overrides(cfg, args)
    out = writable_dir(Path(args.out or f"runs/{name}"))
    with output_lock(out, "train"):
        try:
            state = train(
                cfg, out, resume=args.resume, overwrite=args.overwrite, progress=not args.quiet
            )
        except KeyboardInterrupt:
            print(f"iout-mj train: stopped; resume with --resume --out {out}", file=sys.stderr)
            raise
    print(json.dumps(run_summary(cfg, out, state), indent=2))
    return 0


def cmd_train_marl(args: argparse.Namespace) -> int:
    """MAPPO or IPPO (`training.marl`): the run folder gets checkpoint/, policy/, curve.json."""
    try:
        from iout_mj.training.marl import MarlConfig, train_marl  # heavy: TorchRL
    except ImportError as exc:
        raise UsageError(
            f"train-marl needs TorchRL ({exc}): accepted an install with the mappo extra, "
            "pip install -e '.[mappo]'"
        ) from exc

    cfg = MarlConfig.load(args.marl_config)
    changes: dict[str, Any] = {}
    name = cfg.name
    if args.seed is not None:
        name, changes["seed"] = f"{cfg.name}-seed{args.seed}", args.seed
    if args.steps is not None:
        total = sum(p.agent_steps for p in cfg.phases)
        changes["phases"] = tuple(
            dataclasses.replace(p, agent_steps=max(1, round(p.agent_steps * args.steps / total)))
            for p in cfg.phases
        )
    cfg = dataclasses.replace(cfg, **changes)
    out = writable_dir(Path(args.out or f"runs/{name}"))
    with output_lock(out, "train-marl"):
        summary = train_marl(cfg, out, resume=args.resume, progress=not args.quiet)
    print(json.dumps(summary, indent=2))
    return 0


def train_overrides(cfg: Any, args: argparse.Namespace) -> Any:
    """The training config with the command line's overrides applied, then checked as a whole
    (N, K and the nodes resolve as for any env: a contradiction names both)."""
    from iout_mj.scenarios import read_layout

    changes: dict[str, Any] = {}
    env = load_config(args.config) if args.config is not None else cfg.env
    layout = read_layout(args.nodes_file)
    if layout is not None:  # the nodes, and their seabed depths where the file gives them
        nodes_m, depths_m = layout
        scenario = dataclasses.replace(env.scenario, nodes_m=nodes_m)
        channel = dataclasses.replace(
            env.channel, node_depths_m=depths_m or env.channel.node_depths_m
        )
        env = env.replace(scenario=scenario, channel=channel)
        changes["n_nodes"] = None
    for field in ("seed", "layout", "n_auvs", "torch_threads"):  # flag and field named alike
        if getattr(args, field) is not None:
            changes[field] = getattr(args, field)
    if args.nodes is not None:
        changes["n_nodes"] = args.nodes
    if args.steps is not None:
        total = cfg.total_timesteps
        phases = [
            dataclasses.replace(p, timesteps=max(1, round(p.timesteps * args.steps / total)))
            for p in cfg.phases
        ]
        changes["phases"] = tuple(phases)
    return dataclasses.replace(cfg, env=env, **changes)


def cmd_compare(args: argparse.Namespace) -> int:
    from iout_mj.experiments import compare

    folders = [Path(f) for f in args.results]
    policies = list(dict.fromkeys(args.policy))
    if len(policies) > 1 and not args.grid:
        raise UsageError(
            f"--policy names {len(policies)} policies: accepted one, or several with --grid"
        )
    print(
        f"compare: {args.bootstrap_reps:,} stratified-bootstrap resamples per interval (about "
        "a second per cell) ...",
        file=sys.stderr,
    )
    reps, seed = args.bootstrap_reps, args.bootstrap_seed
    if args.grid:
        found = compare.grid(folders, policies, args.reference, reps, seed)
        print(json.dumps(found, indent=2) if args.json else compare.format_grid(found))
        return 0
    rows, episodes = compare.read_folders(folders)
    one = folders[0] if len(folders) == 1 else None
    result = compare.compare(rows, episodes, policies[0], args.reference, reps, seed, one)
    print(json.dumps(result, indent=2) if args.json else compare.format_markdown(result))
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    from iout_mj.training.checkpoints import export_policy  # heavy: see the module docstring

    out = Path(args.out)
    writable_dir(out.parent)
    kept = export_policy(Path(args.checkpoint), out)
    print(json.dumps({"out": str(out), "eval_at_selection": kept["eval_at_selection"]}, indent=2))
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    from iout_mj.experiments import bench, bench_report  # heavy: see the module docstring

    out = writable_dir(Path(args.out)) if args.out else None
    if args.warp:
        from iout_mj.experiments import bench_warp

        say = lambda stage: print(f"bench: {stage} ...", file=sys.stderr)  # noqa: E731
        warp = bench_warp.run(args.warp_sizes, quick=args.quick, say=say)
        if out:
            _write_json(out / "bench-warp.json", warp)
        print(json.dumps(warp, indent=2) if args.json else bench_warp.format_table(warp))
        return 0
    if args.from_json:
        result = bench_report.read_result(Path(args.from_json))
    else:
        result = bench.run_all(
            quick=args.quick, say=lambda stage: print(f"bench: {stage} ...", file=sys.stderr)
        )
    if out:
        _write_json(out / "bench.json", result)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        report = bench_report.format_markdown if args.markdown else bench_report.format_table
        print(report(result))
    return 0


def _write_json(path: Path, data: Any) -> None:
    """`data` as JSON in `path`, replaced whole; a failed write is a `UsageError`."""
    try:
        write_atomic(path, (json.dumps(data, indent=2) + "\n").encode())
    except OSError as exc:
        raise UsageError(f"cannot write {path}: {exc.strerror or exc}") from exc


def cmd_sweep(args: argparse.Namespace) -> int:
    from iout_mj.experiments import ray_jobs  # ray is optional: imported only when asked

    out = writable_dir(Path(args.out))
    with output_lock(out, "sweep"):
        result = ray_jobs.sweep(args.sweep_config, out, args.ray, args.ray_timeout)
    print(json.dumps(result, indent=2))
    return 0


def cmd_config(args: argparse.Namespace) -> int:
    from iout_mj import config_reference

    if args.markdown:
        print(config_reference.markdown(), end="")
    else:
        print(config_reference.dump_yaml(load_config(args.config)), end="")
    return 0


def cmd_list(args: argparse.Namespace) -> int:
    from iout_mj.agents.registry import POLICIES
    from iout_mj.agents.shipped import shipped_policies
    from iout_mj.backends.registry import BACKENDS
    from iout_mj.scenarios import SCENARIOS
    from iout_mj.vehicles import VEHICLES

    listing = {
        "scenarios": {k: f"K = {s.n_nodes}, layout {s.layout}" for k, s in SCENARIOS.items()},
        "policies": {
            **{k: "baseline" for k in POLICIES},
            **{k: "shipped PPO policy" for k in shipped_policies()},
            "ppo-general": "the shipped general policy for the env's N",
            "mappo": "the shipped MAPPO team policy (decentralised) for the env's N",
            "P+rollout[C]": "a general policy P with decision-time search (C candidates/slot)",
            "P+dock": "any policy P with the docking shield",
        },
        "backends": {k: b.description for k, b in BACKENDS.items()},
        "layouts": {
            "paper": "the paper's nodes for K = 7 and 13, one seeded layout per K otherwise",
            "random": "a new layout every episode",
            "custom": "a config's own scenario.nodes_m, or --nodes-file",
        },
        "vehicles": {v.name: v.summary for v in VEHICLES.values()},
    }
    if args.json:
        print(json.dumps(listing, indent=2))
        return 0
    for group, items in listing.items():
        print(f"{group}:")
        for name, what in items.items():
            print(f"  {name:<22} {what}")
    return 0
