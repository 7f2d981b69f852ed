"""Figures from missions and evaluation results (matplotlib, Agg backend).

Every results figure is titled with its condition (noise model, current and acoustic channel
when the results record them, backend, layout, episodes per cell); error bars are 95 %
confidence intervals of the mean over episodes (Student t), clipped to the measure's range.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import yaml
from matplotlib.lines import Line2D
from matplotlib.ticker import MaxNLocator

from iout_mj import palette
from iout_mj.config import PAPER_CHANNEL
from iout_mj.errors import ResultFileError, UsageError
from iout_mj.experiments.result_files import (
    array,
    integer,
    listing,
    load,
    mapping,
    number,
    read_rows,
    text,
)

MEASURES = ("jain", "mean_aoi", "propulsion_energy_j")
"""What the results figures plot from each evaluation row."""
T_975 = (
    *(12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228),
    *(2.201, 2.179, 2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086),
    *(2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042),
)
"""Student's t 97.5 % quantile for 1 to 30 degrees of freedom."""
N_STYLES = ("-", "--", ":", "-.")
N_MARKERS = ("o", "s", "^", "D")
"""Line style and marker of N = 1, 2, 3, 4 AUVs (then again): N is told apart without colour."""
CI_NOTE = "error bars: 95 % CI of the mean over episodes (Student t)"


def trajectory_figure(trace: dict[str, Any], path: Path, title: str = "", ax: Any = None) -> None:
    """AUV paths over the area, nodes (labelled with the data they delivered), dock zone.

    `trace` is `Mission.trace()`. With `ax` the figure is drawn there and not saved.
    """
    own = ax is None
    if own:
        fig, ax = plt.subplots(figsize=(5.2, 5.2))
    dock = plt.Circle(
        trace["dock_center_m"],
        trace["dock_radius_m"],
        color="tab:green",
        alpha=0.25,
        label="dock zone",
    )
    ax.add_patch(dock)
    pos = np.array(trace["positions_m"])  # (slots + 1, N, 2)
    for i in range(pos.shape[1]):
        c = palette.auv_rgba(i)
        ax.plot(pos[:, i, 0], pos[:, i, 1], "-", color=c, lw=1.6, label=f"AUV {i + 1}")
        ax.plot(pos[0, i, 0], pos[0, i, 1], "o", color=c, ms=5)
        ax.plot(pos[-1, i, 0], pos[-1, i, 1], "s", color=c, ms=5)
    nodes = np.array(trace["nodes_m"])
    bits = np.array(trace["delivered_bits_per_node"]) / 1e6
    ax.scatter(
        nodes[:, 0],
        nodes[:, 1],
        s=60,
        color=palette.NODE_RGB,
        edgecolors="black",
        marker="^",
        zorder=3,
        label="nodes",
    )
    for k, (x, y) in enumerate(nodes):
        right = x > 0.8 * trace["area_m"][0]  # written leftwards, inside the map
        ax.annotate(
            f"{bits[k]:.1f} Mbit",
            (x, y),
            textcoords="offset points",
            xytext=(-5 if right else 5, 6),
            ha="right" if right else "left",
            fontsize=7,
            color="white",
        )
    ax.set(
        xlim=(0, trace["area_m"][0]),
        ylim=(0, trace["area_m"][1]),
        xlabel="x (m)",
        ylabel="y (m)",
        title=title,
        aspect="equal",
    )
    ax.set_facecolor(palette.SEABED_RGB)  # the video's seabed: every AUV colour shows on it
    ax.legend(fontsize=7, loc="lower right")
    ax.grid(alpha=0.3)
    if own:
        fig.tight_layout()
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=130)
        plt.close(fig)


def speed_heading_figure(
    traces: dict[str, dict[str, Any]], path: Path, condition: str = ""
) -> None:
    """Heading and speed of AUV 1 over time for each named trace (paper Fig. 4)."""
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.9))
    if condition:
        fig.suptitle(f"Heading and speed, N = 1 (paper Fig. 4); {condition}", fontsize=10)
    for label, tr in traces.items():
        t = np.arange(len(tr["speeds_mps"])) * tr["slot_s"]
        axes[0].plot(t, np.degrees(np.unwrap(np.array(tr["headings_rad"])[:, 0])), label=label)
        axes[1].plot(t, np.array(tr["speeds_mps"])[:, 0], label=label)
    axes[0].set(xlabel="time (s)", ylabel="heading (deg, unwrapped)", title="Heading, AUV 1")
    axes[1].set(xlabel="time (s)", ylabel="speed (m/s)", title="Speed, AUV 1")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def figures_from_results(
    results: Path | Sequence[Path],
    out: Path,
    skipped: list[str] | None = None,
    labels: Mapping[str, str] | None = None,
    policies: Sequence[str] | None = None,
) -> list[Path]:
    """Every figure one or more folders written by `iout-mj evaluate --out` allow (read
    together: one policy per N evaluated apart, `read_results`); each one it cannot draw is
    said in `skipped`, with the reason.

    Raises:
        ResultFileError: results.json or traces.json is missing a key, holds a non-finite
            number or is not JSON (the message names the file and the entry).
        UsageError: `labels` or `policies` names a policy the results lack, or two folders
            hold the same (policy, N, K).
    """
    folders = [results] if isinstance(results, Path) else list(results)
    rows, traces = read_results(folders, labels or {}, policies)
    traces_path = folders[0] / "traces.json" if len(folders) == 1 else "traces.json"
    notes = skipped if skipped is not None else []
    paths = results_figures(rows, out)
    cond = condition(rows)
    if not traces:
        missing = not any((f / "traces.json").exists() for f in folders)
        why = f"{traces_path} is missing" if missing else f"{traces_path} holds no trajectory"
        notes.append(
            f"skipped Fig. 3 (trajectories) and Fig. 4 (speed and heading): {why}; evaluate "
            "keeps the first episode of each K = 7 cell, or of a config's own nodes"
        )
        return paths
    paths.append(trajectories_figure(traces, out, cond))
    single = {k: v for k, v in traces.items() if k.endswith("N=1")}
    if single:
        p = out / "fig4_speed_heading_n1.png"
        speed_heading_figure(single, p, cond)
        paths.append(p)
    else:
        notes.append(
            "skipped Fig. 4 (speed and heading, N = 1): no trajectory with N = 1 in "
            f"{traces_path} (evaluate with --n-auvs 1)"
        )
    return paths


def read_results(
    folders: Sequence[Path], labels: Mapping[str, str], policies: Sequence[str] | None
) -> tuple[list[dict[str, Any]], dict[str, dict[str, Any]]]:
    """The rows and trajectories of evaluation folders, together: only `policies` (default
    all), each renamed by `labels` (policy -> legend name; one name may gather the policies
    of several N, such as the learned policy of each N evaluated apart)."""
    rows: list[dict[str, Any]] = []
    traces: dict[str, dict[str, Any]] = {}
    for folder in folders:
        hint = f"run `iout-mj evaluate --out {folder}` first"
        folder_rows = read_rows(folder / "results.json", ("policy",), MEASURES, hint)
        for i, row in enumerate(folder_rows):
            integer(row, "episodes", f"{folder / 'results.json'}: row {i}", 1)
        rows += folder_rows
        path = folder / "traces.json"
        traces |= read_traces(path) if path.exists() else {}
    names = sorted({r["policy"] for r in rows})
    for name in [*labels, *(policies or [])]:
        if name not in names:
            raise UsageError(f"figures: no policy {name!r} in the results: accepted {names}")
    keep = set(policies or names)
    rows = [
        r | {"policy": labels.get(r["policy"], r["policy"])} for r in rows if r["policy"] in keep
    ]
    seen: set[tuple[str, int, int]] = set()
    for r in rows:
        key = (r["policy"], r["n_auvs"], r["n_nodes"])
        if key in seen:
            raise UsageError(
                f"figures: the results hold {key[0]!r} at N={key[1]}, K={key[2]} twice: "
                "accepted folders (and --label names) that hold each policy's cell once"
            )
        seen.add(key)
    kept_traces = {}
    for label, trace in traces.items():
        policy, _, rest = label.rpartition(", ")
        if policy in keep:
            kept_traces[f"{labels.get(policy, policy)}, {rest}"] = trace
    return rows, kept_traces


def trajectories_figure(traces: dict[str, dict[str, Any]], out: Path, cond: str) -> Path:
    """One trajectory map per trace (paper Fig. 3), named by the traces' K."""
    ks = sorted({len(tr["nodes_m"]) for tr in traces.values()})
    cols = min(4, len(traces))
    lines = -(-len(traces) // cols)
    fig, axes = plt.subplots(lines, cols, figsize=(4.4 * cols, 4.6 * lines + 0.5), squeeze=False)
    for ax in axes.ravel()[len(traces) :]:
        ax.set_visible(False)
    for ax, (label, tr) in zip(axes.ravel(), sorted(traces.items()), strict=False):
        trajectory_figure(tr, out, title=label, ax=ax)
    k_text = ", ".join(str(k) for k in ks)
    fig.suptitle(
        f"Trajectories and data collected per node, K = {k_text} (paper Fig. 3): the first "
        f"episode of each cell\n{cond}",
        fontsize=10,
    )
    fig.tight_layout()
    p = out / (f"fig3_trajectories_k{ks[0]}.png" if len(ks) == 1 else "fig3_trajectories.png")
    fig.savefig(p, dpi=90)
    plt.close(fig)
    return p


def read_traces(path: Path) -> dict[str, dict[str, Any]]:
    """traces.json (`evaluate.save`): label -> `Mission.trace()`, every array of its shape
    and finite."""
    traces = mapping(load(path, "written by `iout-mj evaluate --out`"), str(path))
    for label, trace in traces.items():
        check_trace(trace, f"{path}: trace {label!r}")
    return traces


def check_trace(trace: Any, where: str) -> None:
    """The entries the trajectory and speed figures read, with consistent shapes."""
    trace = mapping(trace, where)
    pos = array(trace, "positions_m", where, (None, None, 2))
    steps, n_auvs = pos.shape[:2]
    if steps < 1 or n_auvs < 1:
        raise ResultFileError(f"{where}: positions_m is empty: accepted at least one position")
    for key in ("headings_rad", "speeds_mps"):
        array(trace, key, where, (steps, n_auvs))
    n_nodes = array(trace, "nodes_m", where, (None, 2)).shape[0]
    array(trace, "delivered_bits_per_node", where, (n_nodes,))
    array(trace, "dock_center_m", where, (2,))
    if np.any(array(trace, "area_m", where, (2,)) <= 0):
        raise ResultFileError(f"{where}: area_m must be two sizes > 0")
    number(trace, "dock_radius_m", where, 0.0)
    number(trace, "slot_s", where, 0.0)


def read_history(run: Path) -> list[dict[str, Any]]:
    """The evaluation history of a training run (its state.json), each entry checked."""
    path = run / "state.json"
    state = mapping(load(path, "accepted a training run folder (`iout-mj train --out`)"), str(path))
    history = listing(state.get("history"), f"{path}: history")
    for i, raw in enumerate(history):
        where = f"{path}: history[{i}]"
        entry = mapping(raw, where)
        integer(entry, "num_timesteps", where)
        text(entry, "backend", where)
        for key in (
            "mean_aoi_horizon",
            "jain",
            "docking_rate" if "docked" not in entry else "docked",
        ):
            number(entry, key, where)
    return history


def _recipe(run: Path) -> str:
    """The recipe of a run: its config's name (the folder's, without -seed<k>, if it has none)."""
    try:
        config = yaml.safe_load((run / "config.yaml").read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        config = None
    name = config.get("name") if isinstance(config, dict) else None
    return name if isinstance(name, str) else re.sub(r"-seed\d+$", "", run.name)


CURVE_KEYS = ("mean_aoi_horizon", "jain", "docking_rate")


def recipe_curves(runs: list[Path]) -> dict[str, dict[str, Any]]:
    """Per recipe (`_recipe`): its runs' count, the steps of the evaluations every run reached,
    each CURVE_KEYS value per run and evaluation (runs x evaluations), and where its MuJoCo
    phase starts (None without one); every state.json checked first."""
    histories = [(run, read_history(run)) for run in runs]
    groups: dict[str, list[list[dict[str, Any]]]] = {}
    for run, hist in histories:
        groups.setdefault(_recipe(run), []).append(hist)
    curves = {}
    for name, hists in groups.items():
        length = min(len(h) for h in hists)
        first = hists[0][:length]
        kinematic = [e["num_timesteps"] for e in first if e["backend"] == "kinematic"]
        curves[name] = {
            "runs": len(hists),
            "steps": np.array([e["num_timesteps"] for e in first]),
            "mujoco_from": max(kinematic)
            if kinematic and first[-1]["backend"] == "mujoco"
            else None,
            **{
                key: np.array([[e.get(key, e.get("docked")) for e in h[:length]] for h in hists])
                for key in CURVE_KEYS
            },
        }
    return curves


def training_curves(runs: list[Path], path: Path) -> Path:
    """Held-out evaluation during training (each run's state.json) against steps: one line per
    recipe, the mean over its runs (training seeds) with their range shaded; the MuJoCo
    phase's start dotted."""
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    for name, c in recipe_curves(runs).items():
        label = f"{name} ({c['runs']} seeds)" if c["runs"] > 1 else name
        steps = c["steps"] / 1e3
        for ax, key in zip(axes, CURVE_KEYS, strict=True):
            (line,) = ax.plot(steps, c[key].mean(axis=0), marker=".", label=label)
            if c["runs"] > 1:
                ax.fill_between(
                    steps, c[key].min(0), c[key].max(0), color=line.get_color(), alpha=0.2
                )
            if c["mujoco_from"] is not None:  # the fine-tuning phase starts here
                ax.axvline(c["mujoco_from"] / 1e3, color="gray", lw=0.8, ls=":")
    titles = ("mean AoI over T_max (slots, lower is better)", "Jain's index", "docking rate")
    for ax, title in zip(axes, titles, strict=True):
        ax.set(xlabel="training steps (thousands)", title=title)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(
        "PPO: deterministic evaluation on held-out seeds during training (mean over training "
        "seeds, range shaded; dotted: MuJoCo phase)",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def ci95(mean: float, std: float, n: int, low: float, high: float) -> tuple[float, float]:
    """The lower and upper error bar lengths of a 95 % CI of a mean over `n` episodes whose
    population standard deviation is `std` (evaluate's `_std`): t(n - 1) s / sqrt(n) with s the
    sample deviation, clipped to the measure's range [low, high]; none for one episode."""
    if n < 2:
        return 0.0, 0.0
    df = n - 1
    t = T_975[df - 1] if df <= len(T_975) else 1.96 + 2.4 / df
    half = t * std / math.sqrt(df)
    return min(half, max(mean - low, 0.0)), min(half, max(high - mean, 0.0))


def _values(rows: list[dict[str, Any]], key: str) -> list[Any]:
    return sorted({r[key] for r in rows if key in r})


def channel_text(rows: list[dict[str, Any]]) -> str:
    """The acoustic channel of the rows (`ChannelConfig.label`, when they record it): "the
    paper's channel", or "channel: " and its features; "" when no row records it."""
    labels = [str(c) for c in _values(rows, "channel")]
    named = [
        "the paper's channel" if c == PAPER_CHANNEL else "channel: " + c.replace("+", ", ")
        for c in labels
    ]
    return " / ".join(named)


def condition(rows: list[dict[str, Any]]) -> str:
    """The condition of an evaluation, from its rows: noise model and current (when the rows
    record them), backend, layout and episodes per cell; then, on a line of its own, the
    acoustic channel (when the rows record it)."""
    noise = _values(rows, "noise_model")
    parts = [
        " / ".join({"wenz": "Wenz"}.get(n, n) for n in noise) + " noise"
        if noise
        else "noise model not recorded"
    ]
    current = _values(rows, "max_current_mps")
    if current:
        top = max(current)
        parts.append(f"current up to {top:.2g} m/s" if top > 0 else "no current")
    backends = _values(rows, "backend")
    parts.append(" / ".join({"mujoco": "MuJoCo"}.get(b, b) for b in backends) + " backend")
    layouts = {"paper": "paper layouts", "random": "random layouts", "custom": "own nodes"}
    parts.append(" / ".join(layouts.get(x, x) for x in _values(rows, "layout")))
    episodes = _values(rows, "episodes")
    span = str(episodes[0]) if len(episodes) == 1 else f"{episodes[0]}-{episodes[-1]}"
    seeds = max(_values(rows, "training_seeds") or [0])
    parts.append(f"{span} episodes per cell" + (f" ({seeds} training seeds)" if seeds > 1 else ""))
    channel = channel_text(rows)
    return ", ".join(parts) + (f";\n{channel}" if channel else "")


def condition_suffix(rows: list[dict[str, Any]]) -> str:
    """The figure file names' suffix: "_flat", "_wenz" (and "_current" with a current; "" when
    the rows do not record the noise model), then "_channel" when a row's acoustic channel is
    not the paper's."""
    noise = _values(rows, "noise_model")
    current = max(_values(rows, "max_current_mps") or [0.0]) > 0
    tail = "_" + "-".join(noise) + ("_current" if current else "") if noise else ""
    channels = {str(c) for c in _values(rows, "channel")} - {PAPER_CHANNEL}
    return tail + ("_channel" if channels else "")


def vs_k_figure(
    rows: list[dict[str, Any]], key: str, ylabel: str, title: str, high: float, path: Path
) -> Path:
    """`key` against K: a colour per policy, a line style and marker per N, 95 % CIs."""
    policies, ns = _values(rows, "policy"), _values(rows, "n_auvs")
    ks = _values(rows, "n_nodes")
    series = [(p, n) for p in policies for n in ns]
    dodge = 0.04 * (min(np.diff(ks)) if len(ks) > 1 else 1.0)  # error bars side by side
    fig, ax = plt.subplots(figsize=(8.4, 4.6))
    for j, (policy, n) in enumerate(series):
        sel = sorted(
            (r for r in rows if r["policy"] == policy and r["n_auvs"] == n),
            key=lambda r: r["n_nodes"],
        )
        if not sel:
            continue
        bars = np.array([ci95(r[key], r[key + "_std"], r["episodes"], 0.0, high) for r in sel])
        ni = ns.index(n)
        ax.errorbar(
            [r["n_nodes"] + dodge * (j - (len(series) - 1) / 2) for r in sel],
            [r[key] for r in sel],
            yerr=bars.T,
            color=f"C{policies.index(policy)}",
            ls=N_STYLES[ni % len(N_STYLES)],
            marker=N_MARKERS[ni % len(N_MARKERS)],
            ms=5,
            capsize=3,
        )
    if len(ks) <= 12:
        ax.set_xticks(ks)  # the K evaluated
    else:
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set(xlabel="number of nodes K", ylabel=ylabel)
    if high < math.inf:
        ax.set_ylim(top=high + 0.02 * high)
    ax.grid(alpha=0.3)
    by_policy = [Line2D([], [], color=f"C{i}", lw=2.5, label=p) for i, p in enumerate(policies)]
    by_n = [
        Line2D(
            [],
            [],
            color="black",
            ls=N_STYLES[i % len(N_STYLES)],
            marker=N_MARKERS[i % len(N_MARKERS)],
            label=f"N = {n}",
        )
        for i, n in enumerate(ns)
    ]
    fig.legend(handles=by_policy, title="policy", loc="upper left", bbox_to_anchor=(0.78, 0.86))
    fig.legend(handles=by_n, title="AUVs", loc="lower left", bbox_to_anchor=(0.78, 0.16))
    ax.set_title(f"{title}\n{condition(rows)}", fontsize=9)
    fig.text(0.01, 0.01, CI_NOTE + (", clipped to [0, 1]" if high == 1.0 else ""), fontsize=7)
    fig.subplots_adjust(left=0.1, right=0.76, top=0.86, bottom=0.16)  # legends at the right
    fig.savefig(path, dpi=150, bbox_inches="tight", pad_inches=0.1)  # a long name widens it
    plt.close(fig)
    return path


def results_figures(rows: list[dict[str, Any]], out: Path) -> list[Path]:
    """Jain and mean AoI vs K per policy and N (paper Fig. 2), energy per policy; the file
    names carry the noise model (`condition_suffix`)."""
    out.mkdir(parents=True, exist_ok=True)
    tail = condition_suffix(rows)
    paths = [
        vs_k_figure(
            rows,
            "jain",
            "Jain's fairness index",
            "Jain's fairness index vs K (paper Fig. 2a)",
            1.0,
            out / f"fig2a_jain_vs_k{tail}.png",
        ),
        vs_k_figure(
            rows,
            "mean_aoi",
            "mean AoI until the mission ends (slots)",
            "Mean AoI vs K (paper Fig. 2b)",
            math.inf,
            out / f"fig2b_aoi_vs_k{tail}.png",
        ),
    ]
    fig, ax = plt.subplots(figsize=(7, 4))
    labels = sorted({(r["policy"], r["n_auvs"]) for r in rows})
    energy = [
        np.mean([r["propulsion_energy_j"] for r in rows if (r["policy"], r["n_auvs"]) == lab]) / 1e3
        for lab in labels
    ]
    ks = ", ".join(str(k) for k in _values(rows, "n_nodes"))
    ax.bar([f"{p}\nN={n}" for p, n in labels], energy, color="tab:gray")
    ax.set(
        ylabel="propulsion energy per AUV (kJ)",
        title=f"Propulsion energy per AUV, mean over K = {ks}\n{condition(rows)}",
    )
    ax.title.set_fontsize(9)
    ax.tick_params(axis="x", labelsize=7)
    fig.tight_layout()
    p = out / f"energy_per_policy{tail}.png"
    fig.savefig(p, dpi=150)
    plt.close(fig)
    paths.append(p)
    return paths


def energy_validation_figure(result: dict[str, Any], traces: list, path: Path) -> None:
    """Steady-state power vs speed, per-slot energy of the short manoeuvres, and of a whole
    mission (validate-energy's traces: (name, run) pairs, a mission's name starting with
    "mission"); measured (MuJoCo) solid, the paper's model dashed."""
    fig, axes = plt.subplots(1, 3, figsize=(16, 5.6), width_ratios=(1, 1.15, 1.15))
    steady = result["steady"]
    v = [r["speed_mps"] for r in steady]
    axes[0].plot(v, [r["model_power_w"] for r in steady], "-", label="paper model (cubic)")
    axes[0].plot(v, [r["measured_power_w"] for r in steady], "o", label="MuJoCo, measured")
    axes[0].set(
        xlabel="speed (m/s)",
        ylabel="electrical power (W)",
        title="(a) Steady state: power vs speed",
    )
    axes[0].legend(fontsize=8)
    short = [(n, r) for n, r in traces if not n.startswith("mission")]
    whole = [(n, r) for n, r in traces if n.startswith("mission")]
    panels = (
        (axes[1], short, "(b) Manoeuvres: energy per slot", 0),
        (axes[2], whole, "(c) A whole mission: energy per slot", len(short)),
    )
    style = [
        Line2D([], [], color="black", ls="-", label="MuJoCo, measured"),
        Line2D([], [], color="black", ls="--", label="paper model (eq. 13)"),
    ]
    for ax, runs, title, first in panels:
        for i, (name, r) in enumerate(runs):
            slots = np.arange(1, len(r["measured_j"]) + 1)
            color = f"C{first + i}"
            ax.plot(slots, r["measured_j"] / 1e3, "-", color=color, label=name)
            ax.plot(slots, r["model_j"] / 1e3, "--", color=color)
        ax.set(xlabel="slot", ylabel="energy per slot (kJ)", title=title)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        handles = [*ax.get_legend_handles_labels()[0], *style]
        ax.legend(
            handles=handles,
            fontsize=7,
            title="colour: manoeuvre; line style: measured or model",
            title_fontsize=8,
            loc="upper center",
            bbox_to_anchor=(0.5, -0.16),
            ncol=2,
        )
    for ax in axes:
        ax.grid(alpha=0.3)
    dt = result.get("timestep", {}).get("configured_dt_s")
    fig.suptitle(
        "Cubic propulsion model (paper) vs MuJoCo-measured energy, one AUV"
        + (f", dt = {dt:g} s" if dt is not None else ""),
        fontsize=11,
    )
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
