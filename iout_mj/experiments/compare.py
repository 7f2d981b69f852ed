"""A policy against a reference in every cell of an evaluation: the interquartile mean of
AoI(Tmax) over the cell's runs (training seeds x episodes) with 95 % stratified-bootstrap
confidence intervals, the ratio of the IQMs, the probability that the policy's AoI is lower
than the reference's, docking rates and data; then the same over all cells (`statistics`:
rliable). The reference `best-planner` is, in every cell, the baseline with the lowest mean
AoI(Tmax) there.

Reads results.json (the cells, docking and data) and episodes.json (the runs) of one or more
folders written by `iout-mj evaluate --out`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from iout_mj.agents.registry import POLICIES
from iout_mj.errors import ResultFileError, UsageError
from iout_mj.experiments import result_files, statistics
from iout_mj.experiments.statistics import REPS, Cell, cell_of

LABELS = ("policy", "layout", "backend")
MEASURES = ("mean_aoi_horizon", "docking_rate", "delivered_bits")
HINT = "accepted a folder written by `iout-mj evaluate --out`"
BEST_PLANNER = "best-planner"
"""The reference that is, in every cell, the baseline with the lowest mean AoI(Tmax) there."""


def read_rows(results: Path) -> list[dict[str, Any]]:
    """The summary rows of an evaluation folder (`iout-mj evaluate --out`), checked: every
    cell's labels, N, K and the compared measures (finite; AoI > 0, the ratio's divisor).

    Raises:
        ResultFileError: naming the file, the row and what is wrong.
    """
    path = results / "results.json"
    rows = result_files.read_rows(path, LABELS, MEASURES, HINT)
    for i, row in enumerate(rows):
        _positive_aoi(row, f"{path}: row {i}")
    return rows


def read_episodes(results: Path) -> list[dict[str, Any]]:
    """The episode rows of an evaluation folder (episodes.json), checked like `read_rows`."""
    path = results / "episodes.json"
    episodes = result_files.read_episodes(path, LABELS, (statistics.MEASURE,), HINT)
    for i, row in enumerate(episodes):
        _positive_aoi(row, f"{path}: episode {i}")
    return episodes


CONDITION = ("noise_model", "max_current_mps", "channel")
"""What a cell's label leaves out and pooled rows must share."""

Part = tuple[Path, dict[str, Any], list[dict[str, Any]]]
"""A folder's row of a policy's cell, and the cell's runs there."""


def read_folders(folders: list[Path]) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The summary and episode rows of one or more evaluation folders, together (policies
    evaluated apart: a learned policy over training seeds, a baseline on its own). A learned
    policy's cell in several folders, each with other training seeds of it under the same
    condition, is pooled: one row whose measures are the means over all its runs.

    Raises:
        ResultFileError: a file is wrong (`read_rows`), or two folders hold the same policy
            in the same cell other than as disjoint training seeds under one condition.
    """
    episodes: list[dict[str, Any]] = []
    held: dict[tuple[str, Cell], list[Part]] = {}
    for folder in folders:
        folder_episodes = read_episodes(folder)
        runs: dict[tuple[str, Cell], list[dict[str, Any]]] = {}
        for e in folder_episodes:
            runs.setdefault(_key(e), []).append(e)
        for row in read_rows(folder):
            key = _key(row)
            part = (folder, row, runs.get(key, []))
            for before in held.get(key, []):
                _check_poolable(key, part, before)
            held.setdefault(key, []).append(part)
        episodes += folder_episodes
    return [_pooled(parts) for parts in held.values()], episodes


def _key(row: dict[str, Any]) -> tuple[str, Cell]:
    return row["policy"], cell_of(row)


def _check_poolable(key: tuple[str, Cell], new: Part, old: Part) -> None:
    (folder, row, runs), (other, first, before) = new, old
    seeds: set[int | None] = {e.get("training_seed") for e in runs}
    earlier: set[int | None] = {e.get("training_seed") for e in before}
    where = f"{folder} and {other} both hold {key[0]!r} at N={key[1][0]}, K={key[1][1]}"
    if not runs or not before:
        raise ResultFileError(f"{where}, but not its episodes in both: {HINT}, unchanged")
    if None in seeds | earlier or seeds & earlier:
        twice = sorted(s for s in seeds & earlier if s is not None)
        shared = "as a baseline" if None in seeds | earlier else f"seeds {twice}"
        raise ResultFileError(
            f"{where} ({shared}): accepted folders that hold each policy's cell once, or a "
            "learned policy's disjoint training seeds (`evaluate --training-seeds`)"
        )
    differ = [c for c in CONDITION if row.get(c) != first.get(c)]
    if differ:
        raise ResultFileError(
            f"{where} under other conditions ({', '.join(differ)}): accepted training seeds "
            "pooled from evaluations of one condition"
        )


def _pooled(parts: list[Part]) -> dict[str, Any]:
    """A cell's row, or its rows from several folders as one: each measure the mean over all
    the runs (a folder's row holds the mean over its own)."""
    if len(parts) == 1:
        return parts[0][1]
    weights = [len(runs) for _, _, runs in parts]
    row = dict(parts[0][1]) | {
        m: float(np.average([r[m] for _, r, _ in parts], weights=weights)) for m in MEASURES
    }
    row["episodes"] = sum(weights)
    row["training_seeds"] = len({e.get("training_seed") for _, _, runs in parts for e in runs})
    return {k: v for k, v in row.items() if not k.endswith("_std")}


def _positive_aoi(row: dict[str, Any], where: str) -> None:
    if row["mean_aoi_horizon"] <= 0:
        raise ResultFileError(
            f"{where}: mean_aoi_horizon is {row['mean_aoi_horizon']}: accepted a number > 0 "
            "(an age of information)"
        )


def references(rows: list[dict[str, Any]], policy: str, reference: str) -> dict[Cell, str]:
    """The reference of every cell that `policy` flew: `reference` where it flew too, or for
    `best-planner` the baseline (other than `policy`) with the lowest mean AoI(Tmax) there."""
    flown = {cell_of(r) for r in rows if r["policy"] == policy}
    chosen: dict[Cell, tuple[float, str]] = {}
    for r in rows:
        cell, name = cell_of(r), r["policy"]
        if cell not in flown:
            continue
        if reference == BEST_PLANNER and name in POLICIES and name != policy:
            if cell not in chosen or r["mean_aoi_horizon"] < chosen[cell][0]:
                chosen[cell] = (r["mean_aoi_horizon"], name)
        elif name == reference:
            chosen[cell] = (r["mean_aoi_horizon"], name)
    if not chosen:
        holds = "a baseline besides it" if reference == BEST_PLANNER else repr(reference)
        raise UsageError(
            f"no cell holds both {policy!r} and {holds}: accepted a --policy and --reference "
            f"(a policy name, or {BEST_PLANNER}) that the results hold in the same cells"
        )
    return {cell: name for cell, (_, name) in sorted(chosen.items())}


def _runs(runs: dict[Cell, np.ndarray], name: str, cell: Cell, results: Path | None) -> np.ndarray:
    if cell not in runs:
        raise ResultFileError(
            f"{results or 'the results'}: episodes.json holds no episode of {name!r} at "
            f"N={cell[0]}, K={cell[1]} that results.json summarises: {HINT}, unchanged"
        )
    return runs[cell]


def compare(
    rows: list[dict[str, Any]],
    episodes: list[dict[str, Any]],
    policy: str,
    reference: str,
    reps: int = REPS,
    seed: int = 0,
    results: Path | None = None,
) -> dict[str, Any]:
    """Per cell (N, K, layout, backend) that both policies flew: IQM AoI(Tmax) [95 % CI] of
    each, their ratio, P(policy AoI < reference AoI) [CI], docking rates and Mbit; then the
    aggregate over those cells (`statistics.comparison`); the bootstrap is seeded by `seed`.

    Raises:
        UsageError: the policy is its own reference, no cell holds both, or the cells hold
            unequal numbers of runs.
    """
    if policy == reference:
        raise UsageError(
            f"policy and reference are both {policy!r}: accepted two different policies (or "
            f"the reference {BEST_PLANNER})"
        )
    refs = references(rows, policy, reference)
    summary = {(r["policy"], cell_of(r)): r for r in rows}
    mine_runs = statistics.aoi_runs(episodes, policy)
    runs_of = {name: statistics.aoi_runs(episodes, name) for name in set(refs.values())}
    aoi = [_runs(mine_runs, policy, cell, results) for cell in refs]
    theirs = [_runs(runs_of[name], name, cell, results) for cell, name in refs.items()]
    cells, total = statistics.comparison(aoi, theirs, reps, seed)
    table = []
    for (cell, name), stats in zip(refs.items(), cells, strict=True):
        mine, ref = summary[(policy, cell)], summary[(name, cell)]
        table.append(
            {
                "n_auvs": cell[0],
                "n_nodes": cell[1],
                "layout": cell[2],
                "backend": cell[3],
                "reference": name,
                **stats,
                "mean_ratio": mine["mean_aoi_horizon"] / ref["mean_aoi_horizon"],
                "policy_docked": mine["docking_rate"],
                "reference_docked": ref["docking_rate"],
                "policy_mbit": mine["delivered_bits"] / 1e6,
                "reference_mbit": ref["delivered_bits"] / 1e6,
            }
        )
    played = {e["seed"] for e in episodes if e["policy"] == policy}
    total |= {
        "training_seeds": statistics.training_seeds(episodes, policy),
        "episodes": len(played),
        "reference_runs_per_cell": min(len(t) for t in theirs),
    }
    bootstrap = {"method": "stratified", "reps": reps, "seed": seed}
    return {
        "policy": policy,
        "reference": reference,
        "confidence": statistics.CONFIDENCE,
        "bootstrap": bootstrap,
        "cells": table,
        "aggregate": total,
    }


def format_markdown(result: dict[str, Any]) -> str:
    """The per-cell table, then the aggregate line."""
    policy, reference = result["policy"], result["reference"]
    best = reference == BEST_PLANNER
    ref = "best planner" if best else reference
    lines = [
        f"| N | K |{' best planner |' if best else ''} {policy} IQM AoI(Tmax) [95 % CI] "
        f"| {ref} IQM AoI(Tmax) [95 % CI] | ratio | P({policy} < {ref}) [95 % CI] | docked "
        f"| docked ({ref}) | Mbit | Mbit ({ref}) |",
        "|---|---|" + ("---|" if best else "") + "---|---|---|---|---|---|---|---|",
    ]
    for r in result["cells"]:
        named = f" {r['reference']} |" if best else ""
        lines.append(
            f"| {r['n_auvs']} | {r['n_nodes']} |{named} {_ci(r, 'policy_aoi_iqm')} "
            f"| {_ci(r, 'reference_aoi_iqm')} | {r['ratio']:.3f} | {_ci(r, 'p_improvement')} "
            f"| {r['policy_docked']:.0%} | {r['reference_docked']:.0%} "
            f"| {r['policy_mbit']:.1f} | {r['reference_mbit']:.1f} |"
        )
    return "\n".join(lines) + "\n\n" + _aggregate_line(result)


def grid(
    folders: list[Path], policies: list[str], reference: str, reps: int = REPS, seed: int = 0
) -> dict[str, Any]:
    """Every policy against the reference in each folder, a folder a condition (noise,
    currents: the same cells evaluated apart): `compare` per folder and policy, for one table
    of the cells by condition."""
    columns = []
    for folder in folders:
        rows, episodes = read_folders([folder])
        found = [compare(rows, episodes, p, reference, reps, seed, folder) for p in policies]
        columns.append({"results": str(folder), "comparisons": found})
    return {"policies": policies, "reference": reference, "columns": columns}


def format_grid(result: dict[str, Any]) -> str:
    """The cells by condition: in each, every policy's IQM ratio to the reference (first / second
    / ...) and the first policy's data as a share of the reference's; then per condition the
    aggregate and how many cells the first policy is below the reference in."""
    policies, columns = result["policies"], result["columns"]
    names = [Path(c["results"]).name for c in columns]
    by_cell = [
        [{cell_of(r): r for r in comparison["cells"]} for comparison in c["comparisons"]]
        for c in columns
    ]
    keys = sorted({key for column in by_cell for key in column[0]})
    head = "| N | K | layout | backend | "
    lines = [head + " | ".join(names) + " |", "|---" * (4 + len(names)) + "|"]
    for key in keys:
        entries = [_grid_entry(column, key) for column in by_cell]
        lines.append("| " + " | ".join(map(str, key)) + " | " + " | ".join(entries) + " |")
    ref = "the best planner" if result["reference"] == BEST_PLANNER else result["reference"]
    lines += [
        "",
        f"In each cell: the IQM of AoI(Tmax) of {' / '.join(policies)} over {ref}'s, and "
        f"{policies[0]}'s data as a share of {ref}'s.",
    ]
    for name, column in zip(names, columns, strict=True):
        found = column["comparisons"]
        cells = found[0]["cells"]
        aggregates = " / ".join(_ci(c["aggregate"], "normalised_aoi_iqm") for c in found)
        lines.append(
            f"{name}: aggregate {aggregates}; {policies[0]} below {ref} in "
            f"{sum(c['ratio'] < 1 for c in cells)} of {len(cells)} cells on the IQM, "
            f"{sum(c['mean_ratio'] < 1 for c in cells)} on the mean, docked in at least 95 % in "
            f"{sum(c['policy_docked'] >= 0.95 for c in cells)}, at least the data in "
            f"{sum(c['policy_mbit'] >= c['reference_mbit'] for c in cells)}"
        )
    return "\n".join(lines)


def _grid_entry(column: list[dict[Cell, dict[str, Any]]], key: Cell) -> str:
    if key not in column[0]:
        return "-"
    ratios = " / ".join(f"{c[key]['ratio']:.3f}" if key in c else "-" for c in column)
    first = column[0][key]
    return f"{ratios}, {100 * first['policy_mbit'] / first['reference_mbit']:.1f} %"


def _ci(row: dict[str, Any], key: str) -> str:
    return f"{row[key]:.2f} [{row[key + '_low']:.2f}, {row[key + '_high']:.2f}]"


def _aggregate_line(result: dict[str, Any]) -> str:
    policy, total, boot = result["policy"], result["aggregate"], result["bootstrap"]
    ref = "the best planner" if result["reference"] == BEST_PLANNER else result["reference"]
    seeds, cells, episodes = total["training_seeds"], total["cells"], total["episodes"]
    flown = f"{episodes} episode{_s(episodes)}"
    runs = f"{seeds} training seed{_s(seeds)} x {flown}" if seeds else f"{flown}, no training seeds"
    per_cell = total["runs_per_cell"]
    return (
        f"aggregate over {cells} cell{_s(cells)}: IQM of AoI(Tmax) / {ref}'s mean AoI(Tmax) in "
        f"the cell {_ci(total, 'normalised_aoi_iqm')} (lower is better), "
        f"P({policy} < {ref}) {_ci(total, 'p_improvement')}; {policy}: {runs} = "
        f"{per_cell} run{_s(per_cell)} per cell, {ref}: {total['reference_runs_per_cell']}; "
        f"{result['confidence'] * 100:g} % CIs by stratified bootstrap "
        f"({boot['reps']:,} resamples, seed {boot['seed']}; rliable)"
    )


def _s(count: int) -> str:
    return "" if count == 1 else "s"
