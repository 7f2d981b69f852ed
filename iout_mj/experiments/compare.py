"""A learned policy against a reference in every cell of an evaluation: the generalisation
table (mean AoI over T_max, their ratio, docking rates)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from iout_mj.errors import ResultFileError, UsageError
from iout_mj.experiments import result_files

LABELS = ("policy", "layout", "backend")
MEASURES = ("mean_aoi_horizon", "docking_rate", "delivered_bits")


def read_rows(results: Path) -> list[dict[str, Any]]:
    """The summary rows of an evaluation folder (`iout-mj evaluate --out`), checked: every
    cell's labels, N, K and the compared measures (finite; AoI > 0, the ratio's divisor).

    Raises:
        ResultFileError: naming the file, the row and what is wrong.
    """
    path = results / "results.json"
    rows = result_files.read_rows(
        path, LABELS, MEASURES, "accepted a folder written by `iout-mj evaluate --out`"
    )
    for i, row in enumerate(rows):
        if row["mean_aoi_horizon"] <= 0:
            raise ResultFileError(
                f"{path}: row {i}: mean_aoi_horizon is {row['mean_aoi_horizon']}: accepted a "
                "number > 0 (an age of information)"
            )
    return rows


def compare(rows: list[dict[str, Any]], policy: str, reference: str) -> list[dict[str, Any]]:
    """One row per (N, K, layout, backend) that both policies flew."""
    by_cell = {(r["policy"], r["n_auvs"], r["n_nodes"], r["layout"], r["backend"]): r for r in rows}
    out = []
    for (name, n, k, layout, backend), row in sorted(by_cell.items()):
        ref = by_cell.get((reference, n, k, layout, backend))
        if name != policy or ref is None:
            continue
        out.append(
            {
                "n_auvs": n,
                "n_nodes": k,
                "layout": layout,
                "policy_aoi": row["mean_aoi_horizon"],
                "policy_aoi_std": row["mean_aoi_horizon_std"],
                "reference_aoi": ref["mean_aoi_horizon"],
                "reference_aoi_std": ref["mean_aoi_horizon_std"],
                "ratio": row["mean_aoi_horizon"] / ref["mean_aoi_horizon"],
                "policy_docked": row["docking_rate"],
                "reference_docked": ref["docking_rate"],
                "policy_mbit": row["delivered_bits"] / 1e6,
                "reference_mbit": ref["delivered_bits"] / 1e6,
            }
        )
    if not out:
        raise UsageError(f"no cell holds both {policy!r} and {reference!r}")
    return out


def format_markdown(table: list[dict[str, Any]], policy: str, reference: str) -> str:
    lines = [
        f"| N | K | {policy} AoI(Tmax) | {reference} AoI(Tmax) | ratio | docked "
        f"| docked ({reference}) | Mbit | Mbit ({reference}) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in table:
        lines.append(
            f"| {r['n_auvs']} | {r['n_nodes']} | {r['policy_aoi']:.2f} ± {r['policy_aoi_std']:.2f} "
            f"| {r['reference_aoi']:.2f} ± {r['reference_aoi_std']:.2f} | {r['ratio']:.3f} "
            f"| {r['policy_docked']:.0%} | {r['reference_docked']:.0%} "
            f"| {r['policy_mbit']:.1f} | {r['reference_mbit']:.1f} |"
        )
    return "\n".join(lines)
