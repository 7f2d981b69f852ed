"""Figures from missions and evaluation results (matplotlib, Agg backend)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from iout_mj import palette
from iout_mj.errors import ResultFileError
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
    ax.scatter(nodes[:, 0], nodes[:, 1], s=60, c="tab:blue", marker="^", zorder=3, label="nodes")
    for k, (x, y) in enumerate(nodes):
        ax.annotate(
            f"{bits[k]:.1f} Mbit", (x, y), textcoords="offset points", xytext=(5, 6), fontsize=7
        )
    ax.set(
        xlim=(0, trace["area_m"][0]),
        ylim=(0, trace["area_m"][1]),
        xlabel="x (m)",
        ylabel="y (m)",
        title=title,
        aspect="equal",
    )
    ax.legend(fontsize=7, loc="lower right")
    ax.grid(alpha=0.3)
    if own:
        fig.tight_layout()
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=130)
        plt.close(fig)


def speed_heading_figure(traces: dict[str, dict[str, Any]], path: Path) -> None:
    """Heading and speed of AUV 1 over time for each named trace (paper Fig. 4)."""
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
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


def figures_from_results(results: Path, out: Path) -> list[Path]:
    """All figures from a folder written by `iout-mj evaluate --out`.

    Raises:
        ResultFileError: results.json or traces.json is missing a key, holds a non-finite
            number or is not JSON (the message names the file and the entry).
    """
    hint = f"run `iout-mj evaluate --out {results}` first"
    rows = read_rows(results / "results.json", ("policy",), MEASURES, hint)
    traces_path = results / "traces.json"
    traces = read_traces(traces_path) if traces_path.exists() else {}
    paths = results_figures(rows, out)
    if traces:
        cols = min(4, len(traces))
        lines = -(-len(traces) // cols)
        fig, axes = plt.subplots(lines, cols, figsize=(4.4 * cols, 4.6 * lines), squeeze=False)
        for ax in axes.ravel()[len(traces) :]:
            ax.set_visible(False)
        for ax, (label, tr) in zip(axes.ravel(), sorted(traces.items()), strict=False):
            trajectory_figure(tr, out, title=label, ax=ax)
        fig.suptitle("Trajectories and data collected per node, K = 7 (paper Fig. 3)")
        fig.tight_layout()
        p = out / "fig3_trajectories_k7.png"
        fig.savefig(p, dpi=90)
        plt.close(fig)
        paths.append(p)
        single = {k: v for k, v in traces.items() if k.endswith("N=1")}
        if single:
            p = out / "fig4_speed_heading_n1.png"
            speed_heading_figure(single, p)
            paths.append(p)
    return paths


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


def training_curves(runs: list[Path], path: Path) -> Path:
    """Held-out evaluation during training (from each run's state.json) against steps."""
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    histories = [(run, read_history(run)) for run in runs]  # every file checked before drawing
    for run, hist in histories:
        steps = np.array([h["num_timesteps"] for h in hist]) / 1e3
        for ax, key in zip(axes, ("mean_aoi_horizon", "jain", "docking_rate"), strict=True):
            ax.plot(steps, [h.get(key, h.get("docked")) for h in hist], marker=".", label=run.name)
        kinematic = [h["num_timesteps"] / 1e3 for h in hist if h["backend"] == "kinematic"]
        if kinematic and hist[-1]["backend"] == "mujoco":  # the fine-tuning phase starts here
            for ax in axes:
                ax.axvline(max(kinematic), color="gray", lw=0.8, ls=":")
    titles = ("mean AoI over T_max (slots)", "Jain's index", "docking rate")
    for ax, title in zip(axes, titles, strict=True):
        ax.set(xlabel="training steps (thousands)", title=title)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("PPO: deterministic evaluation on 10 held-out seeds (dotted: MuJoCo phase)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def results_figures(rows: list[dict[str, Any]], out: Path) -> list[Path]:
    """Jain and mean AoI vs K per policy and N (paper Fig. 2), energy per policy."""
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for key, ylabel, fname in (
        ("jain", "Jain's fairness index", "fig2a_jain_vs_k.png"),
        ("mean_aoi", "mean AoI (slots)", "fig2b_aoi_vs_k.png"),
    ):
        fig, ax = plt.subplots(figsize=(5, 3.8))
        for policy, n in sorted({(r["policy"], r["n_auvs"]) for r in rows}):
            sel = sorted(
                (r for r in rows if r["policy"] == policy and r["n_auvs"] == n),
                key=lambda r: r["n_nodes"],
            )
            k = [r["n_nodes"] for r in sel]
            ax.errorbar(
                k,
                [r[key] for r in sel],
                yerr=[r[key + "_std"] for r in sel],
                marker="o",
                capsize=3,
                label=f"{policy}, N={n}",
            )
        ax.set(xlabel="number of nodes K", ylabel=ylabel)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
        fig.tight_layout()
        p = out / fname
        fig.savefig(p, dpi=150)
        plt.close(fig)
        paths.append(p)
    fig, ax = plt.subplots(figsize=(6, 3.6))
    labels = sorted({(r["policy"], r["n_auvs"]) for r in rows})
    energy = [
        np.mean([r["propulsion_energy_j"] for r in rows if (r["policy"], r["n_auvs"]) == lab]) / 1e3
        for lab in labels
    ]
    ax.bar([f"{p}\nN={n}" for p, n in labels], energy, color="tab:gray")
    ax.set(ylabel="propulsion energy per AUV (kJ)", title="Propulsion energy (mean over K)")
    ax.tick_params(axis="x", labelsize=7)
    fig.tight_layout()
    p = out / "energy_per_policy.png"
    fig.savefig(p, dpi=150)
    plt.close(fig)
    paths.append(p)
    return paths


def energy_validation_figure(result: dict[str, Any], traces: list, path: Path) -> None:
    """Steady-state power vs speed, and per-slot energy of the manoeuvres (validate-energy)."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    steady = result["steady"]
    v = [r["speed_mps"] for r in steady]
    axes[0].plot(v, [r["model_power_w"] for r in steady], "-", label="paper model (cubic)")
    axes[0].plot(v, [r["measured_power_w"] for r in steady], "o", label="MuJoCo, measured")
    axes[0].set(
        xlabel="speed (m/s)", ylabel="electrical power (W)", title="Steady state: power vs speed"
    )
    axes[0].legend()
    axes[0].grid(alpha=0.3)
    ax = axes[1]
    for i, (name, r) in enumerate(traces):
        slots = np.arange(1, len(r["measured_j"]) + 1)
        line = ax.plot(slots, r["measured_j"] / 1e3, "-", color=f"C{i}", label=f"{name}")
        ax.plot(slots, r["model_j"] / 1e3, "--", color=line[0].get_color())
    ax.set(
        xlabel="slot",
        ylabel="energy per slot (kJ)",
        title="Manoeuvres: measured (solid) vs model (dashed)",
    )
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=130)
    plt.close(fig)
