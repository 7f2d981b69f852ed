"""Statistics of evaluation episodes as Agarwal et al. (2021, "Deep RL at the edge of the
statistical precipice") recommend, computed by their `rliable`: the interquartile mean (IQM)
of AoI(Tmax) with 95 % stratified-bootstrap confidence intervals, and the probability of
improvement of a policy over a reference.

A run is one episode of one training seed: a cell's runs pool its training seeds and episodes.
Score matrices are runs x cells, as rliable takes them. rliable 1.2 draws its bootstrap
indices from numpy's global RNG (its `random_state` does not reach them), so every estimate
seeds that RNG with `seed` and gives it back its state afterwards: the same rows and seed give
the same intervals.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from rliable import library, metrics

from iout_mj.errors import UsageError

REPS = 2000
"""Bootstrap resamples of every interval by default."""
CONFIDENCE = 0.95
MEASURE = "mean_aoi_horizon"
"""The compared score: the mean AoI over T_max of an episode (lower is better)."""

Cell = tuple[int, int, str, str]
"""(N, K, layout, backend) of an evaluation."""


@dataclass(frozen=True)
class Estimate:
    """A point estimate and its confidence interval [low, high]."""

    value: float
    low: float
    high: float

    def fields(self, prefix: str) -> dict[str, float]:
        """{prefix: value, prefix_low: low, prefix_high: high} (JSON rows)."""
        return {
            prefix if key == "value" else f"{prefix}_{key}": v for key, v in asdict(self).items()
        }


@contextmanager
def _seeded(seed: int) -> Iterator[None]:
    """numpy's global RNG seeded with `seed` (rliable's bootstrap draws from it), then restored."""
    state = np.random.get_state()
    np.random.seed(seed)
    try:
        yield
    finally:
        np.random.set_state(state)


def _estimates(
    scores: np.ndarray | list[np.ndarray],
    func: Callable[..., np.ndarray],
    reps: int,
    seed: int,
) -> list[Estimate]:
    """rliable's point estimates of the vector `func` and their stratified-bootstrap intervals:
    one score matrix (runs x tasks) resampled by runs within each task, or a list of them, each
    resampled so (independently of the others)."""
    with _seeded(seed):
        point, interval = library.get_interval_estimates(
            {"x": scores}, func, reps=reps, confidence_interval_size=CONFIDENCE
        )
    low, high = interval["x"]
    return [Estimate(*map(float, v)) for v in zip(point["x"], low, high, strict=True)]


def _column(runs: np.ndarray) -> np.ndarray:
    """One cell's runs as a runs x 1 score matrix."""
    return np.asarray(runs, dtype=float).reshape(-1, 1)


def iqm(scores: np.ndarray, reps: int = REPS, seed: int = 0) -> Estimate:
    """The IQM (25 % trimmed mean over all runs and tasks) of a runs x tasks matrix, with its
    95 % CI by a bootstrap of the runs stratified by task."""
    func = lambda s: np.array([metrics.aggregate_iqm(s)])  # noqa: E731
    return _estimates(np.asarray(scores, dtype=float), func, reps, seed)[0]


def probability_of_improvement(
    aoi: np.ndarray, reference_aoi: np.ndarray, reps: int = REPS, seed: int = 0
) -> Estimate:
    """P(AoI < reference AoI) per task, averaged over tasks (rliable's definition: ties count
    one half), with its 95 % CI (each matrix's runs resampled independently within each task).
    rliable's scores are higher-is-better: it is given the AoI negated. Both matrices are
    runs x tasks with the same tasks; their run counts may differ."""
    func = lambda x, y: np.array([metrics.probability_of_improvement(x, y)])  # noqa: E731
    scores = [-np.asarray(aoi, dtype=float), -np.asarray(reference_aoi, dtype=float)]
    return _estimates(scores, func, reps, seed)[0]


def cells_iqm(runs: list[np.ndarray], reps: int = REPS, seed: int = 0) -> list[Estimate]:
    """The IQM of every cell's runs with its CI, in one bootstrap (each cell resampled on its
    own, as a stratified bootstrap of a runs x cells matrix does; the counts may differ)."""
    func = lambda *cells: np.array([metrics.aggregate_iqm(c) for c in cells])  # noqa: E731
    return _estimates([_column(r) for r in runs], func, reps, seed)


def cells_improvement(
    aoi: list[np.ndarray], reference_aoi: list[np.ndarray], reps: int = REPS, seed: int = 0
) -> tuple[list[Estimate], Estimate]:
    """P(AoI < reference AoI) in every cell (one run vector per cell, the same cell order for
    both) and its average over cells (rliable's probability of improvement of the runs x cells
    matrices), each with its CI, from one bootstrap that resamples every cell's runs of each
    policy on their own (run counts may differ between cells)."""
    columns = [-_column(r) for pair in zip(aoi, reference_aoi, strict=True) for r in pair]

    def func(*cells: np.ndarray) -> np.ndarray:
        pairs = zip(cells[::2], cells[1::2], strict=True)
        each = [metrics.probability_of_improvement(x, y) for x, y in pairs]
        return np.array([*each, np.mean(each)])

    *each, mean = _estimates(columns, func, reps, seed)
    return each, mean


def cell_of(row: dict[str, Any]) -> Cell:
    return (row["n_auvs"], row["n_nodes"], row["layout"], row["backend"])


def aoi_runs(episodes: list[dict[str, Any]], policy: str) -> dict[Cell, np.ndarray]:
    """The AoI(Tmax) of every run of `policy` per cell, in (training seed, episode seed) order."""
    runs: dict[Cell, list[tuple[int, int, float]]] = {}
    for e in episodes:
        if e["policy"] == policy:
            trained = e.get("training_seed")
            key = (-1 if trained is None else trained, e["seed"], float(e[MEASURE]))
            runs.setdefault(cell_of(e), []).append(key)
    return {cell: np.array([r[2] for r in sorted(rs)]) for cell, rs in runs.items()}


def training_seeds(episodes: list[dict[str, Any]], policy: str) -> int:
    """How many training seeds of `policy` the rows hold (0: a baseline, or older results)."""
    seeds = {e.get("training_seed") for e in episodes if e["policy"] == policy}
    return len(seeds - {None})


def score_matrix(columns: list[np.ndarray], what: str) -> np.ndarray:
    """Runs x cells from one run vector per cell (`what`'s); cells of unequal run counts are
    refused rather than truncated (rliable's IQM over cells takes a full matrix, and cutting
    runs would drop episodes or training seeds without a trace)."""
    counts = sorted({len(c) for c in columns})
    if len(counts) > 1:
        raise UsageError(
            f"the aggregate over cells needs as many runs of {what} in every cell; its cells hold "
            f"{', '.join(map(str, counts))} runs: accepted cells evaluated alike (one "
            "`iout-mj evaluate` with one --episodes and --training-seeds)"
        )
    return np.stack(columns, axis=1)


def normalised_iqm(
    aoi: list[np.ndarray], reference_aoi: list[np.ndarray], reps: int = REPS, seed: int = 0
) -> Estimate:
    """The IQM over cells of the policy's AoI divided, cell by cell, by the reference's mean
    AoI there (lower is better; 1 is the reference's mean), with its CI stratified by cell."""
    means = np.array([r.mean() for r in reference_aoi])
    return iqm(score_matrix(aoi, "the policy") / means, reps, seed)


def comparison(
    aoi: list[np.ndarray], reference_aoi: list[np.ndarray], reps: int = REPS, seed: int = 0
) -> tuple[list[dict[str, float]], dict[str, float]]:
    """A policy against a reference over cells (one run vector each per cell, the same cell
    order): per cell the IQM AoI of both with their CIs, the ratio of the IQMs and
    P(policy AoI < reference AoI) with its CI; then the aggregate (`normalised_iqm`, the
    probability of improvement averaged over cells)."""
    iqms = cells_iqm([*aoi, *reference_aoi], reps, seed)
    better, overall = cells_improvement(aoi, reference_aoi, reps, seed)
    cells = [
        {
            **mine.fields("policy_aoi_iqm"),
            **theirs.fields("reference_aoi_iqm"),
            "ratio": mine.value / theirs.value,
            **p.fields("p_improvement"),
            "policy_runs": len(a),
            "reference_runs": len(r),
        }
        for mine, theirs, p, a, r in zip(
            iqms[: len(aoi)], iqms[len(aoi) :], better, aoi, reference_aoi, strict=True
        )
    ]
    total = {
        **normalised_iqm(aoi, reference_aoi, reps, seed).fields("normalised_aoi_iqm"),
        **overall.fields("p_improvement"),
        "cells": len(aoi),
        "runs_per_cell": len(aoi[0]),
    }
    return cells, total
