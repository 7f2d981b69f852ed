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

from iout_mj.errors import ResultFileError, UsageError, require_integer, require_seed

REPS = 2000
"""Bootstrap resamples of every interval by default."""
MAX_REPS = 1_000_000
"""Bootstrap resamples at most (each a resample of every score matrix)."""
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
    require_integer(reps, "reps", 1, MAX_REPS)
    require_seed(seed)
    matrices = scores if isinstance(scores, list) else [scores]
    if not matrices:
        raise UsageError("no score matrix: accepted one or more (one per cell)")
    for matrix in matrices:
        _check_scores(matrix)
    with _seeded(seed):
        point, interval = library.get_interval_estimates(
            {"x": scores}, func, reps=reps, confidence_interval_size=CONFIDENCE
        )
    low, high = interval["x"]
    return [Estimate(*map(float, v)) for v in zip(point["x"], low, high, strict=True)]


def _check_scores(matrix: np.ndarray, what: str = "a score matrix") -> None:
    """A score matrix rliable can bootstrap: runs x tasks, at least one of each, finite."""
    if matrix.ndim != 2 or 0 in matrix.shape:
        raise UsageError(
            f"{what}: shape {matrix.shape}; accepted runs x tasks with at least one run and "
            "one task (a cell without episodes has no estimate)"
        )
    if not np.isfinite(matrix).all():
        raise UsageError(
            f"{what}: NaN or infinity; accepted finite scores (an episode whose physics "
            "diverged has no AoI to compare)"
        )


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
    if scores[0].ndim == scores[1].ndim == 2 and scores[0].shape[1] != scores[1].shape[1]:
        raise UsageError(
            f"{scores[0].shape[1]} tasks of the policy and {scores[1].shape[1]} of the "
            "reference: accepted runs x tasks matrices with the same tasks (columns)"
        )
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
    _check_pairs(aoi, reference_aoi)
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
    seen: set[tuple[Cell, int, int]] = set()
    for e in episodes:
        if e["policy"] == policy:
            trained = e.get("training_seed")
            key = (-1 if trained is None else trained, e["seed"], float(e[MEASURE]))
            cell = cell_of(e)
            if (cell, *key[:2]) in seen:
                raise ResultFileError(
                    f"the episodes hold {policy!r} at N={cell[0]}, K={cell[1]}, episode seed "
                    f"{e['seed']}, training seed {trained} more than once: accepted each "
                    "episode once (one evaluation's episodes.json; its runs would count twice)"
                )
            seen.add((cell, *key[:2]))
            runs.setdefault(cell, []).append(key)
    return {cell: np.array([r[2] for r in sorted(rs)]) for cell, rs in runs.items()}


def training_seeds(episodes: list[dict[str, Any]], policy: str) -> int:
    """How many training seeds of `policy` the rows hold (0: a baseline, or older results)."""
    seeds = {e.get("training_seed") for e in episodes if e["policy"] == policy}
    return len(seeds - {None})


def score_matrix(columns: list[np.ndarray], what: str) -> np.ndarray:
    """Runs x cells from one run vector per cell (`what`'s); cells of unequal run counts are
    refused rather than truncated (rliable's IQM over cells takes a full matrix, and cutting
    runs would drop episodes or training seeds without a trace)."""
    if not columns:
        raise UsageError(f"no cell of {what}: accepted one run vector per cell, at least one")
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
    _check_pairs(aoi, reference_aoi, divides=True)
    means = np.array([r.mean() for r in reference_aoi])
    return iqm(score_matrix(aoi, "the policy") / means, reps, seed)


def _check_pairs(
    aoi: list[np.ndarray], reference_aoi: list[np.ndarray], divides: bool = False
) -> None:
    """One non-empty, finite run vector of each per cell, at least one cell; with `divides`
    every reference AoI > 0 (its mean divides)."""
    if not aoi or len(aoi) != len(reference_aoi):
        raise UsageError(
            f"{len(aoi)} cells of the policy and {len(reference_aoi)} of the reference: "
            "accepted one run vector of each per cell, in the same cell order, at least one cell"
        )
    for i, (mine, theirs) in enumerate(zip(aoi, reference_aoi, strict=True)):
        for what, runs in (("policy", mine), ("reference", theirs)):
            _check_scores(_column(runs), f"the {what}'s runs in cell {i}")
        if divides and not (np.asarray(theirs, dtype=float) > 0).all():
            raise UsageError(
                f"cell {i}: the reference's runs hold an AoI <= 0: accepted AoI > 0 (the ratios "
                "divide by the reference's mean)"
            )


def comparison(
    aoi: list[np.ndarray], reference_aoi: list[np.ndarray], reps: int = REPS, seed: int = 0
) -> tuple[list[dict[str, float]], dict[str, float]]:
    """A policy against a reference over cells (one run vector each per cell, the same cell
    order): per cell the IQM AoI of both with their CIs, the ratio of the IQMs and
    P(policy AoI < reference AoI) with its CI; then the aggregate (`normalised_iqm`, the
    probability of improvement averaged over cells)."""
    _check_pairs(aoi, reference_aoi, divides=True)
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
