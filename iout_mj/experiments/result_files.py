"""The JSON files commands read back (evaluation results and traces, a benchmark run, a
training run's state), read safely (`iout_mj.files`) and checked: the expected type, keys and
finite numbers. Anything else raises `ResultFileError` naming the file, the entry and what is
accepted, so `compare`, `figures` and `bench --from-json` never fail half-way through a table
or a figure.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from iout_mj.errors import ResultFileError
from iout_mj.files import read_json
from iout_mj.schema import shown

MAX_RESULT_BYTES = 64 << 20
"""Largest results, traces, benchmark or state file read (a full evaluation is ~1 MB)."""


def load(path: Path, hint: str) -> Any:
    """A result file's JSON; a missing file says what writes it (`hint`)."""
    if not path.exists() and not path.is_symlink():
        raise ResultFileError(f"{path} does not exist: {hint}")
    return read_json(path, MAX_RESULT_BYTES, ResultFileError)


def mapping(value: Any, where: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise ResultFileError(f"{where} is {shown(value)}: accepted a JSON object")
    return value


def listing(value: Any, where: str, min_len: int = 0) -> list[Any]:
    if not isinstance(value, list) or len(value) < min_len:
        raise ResultFileError(
            f"{where} is {shown(value)}: accepted a JSON list of at least {min_len} entries"
        )
    return value


def _get(obj: dict[str, Any], key: str, where: str) -> Any:
    if key not in obj:
        raise ResultFileError(f"{where} has no {key!r}: accepted an entry with {key!r}")
    return obj[key]


def number(obj: dict[str, Any], key: str, where: str, low: float = -math.inf) -> float:
    """A finite number >= `low` under `key`."""
    value = _get(obj, key, where)
    ok = isinstance(value, int | float) and not isinstance(value, bool)
    if not ok or not math.isfinite(value) or value < low:
        bound = "" if low == -math.inf else f" >= {low:g}"
        raise ResultFileError(f"{where}: {key} is {shown(value)}: accepted a finite number{bound}")
    return float(value)


def integer(obj: dict[str, Any], key: str, where: str, low: int = 0) -> int:
    value = _get(obj, key, where)
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise ResultFileError(f"{where}: {key} is {shown(value)}: accepted an integer >= {low}")
    return value


def text(obj: dict[str, Any], key: str, where: str) -> str:
    value = _get(obj, key, where)
    if not isinstance(value, str):
        raise ResultFileError(f"{where}: {key} is {shown(value)}: accepted a string")
    return value


def numbers(obj: dict[str, Any], keys: Iterable[str], where: str, low: float = -math.inf) -> None:
    for key in keys:
        number(obj, key, where, low)


def array(obj: dict[str, Any], key: str, where: str, shape: tuple[int | None, ...]) -> np.ndarray:
    """A finite numeric array under `key` of `shape` (None: any length)."""
    try:
        values = np.asarray(_get(obj, key, where), dtype=np.float64)
    except (TypeError, ValueError) as exc:  # ragged lists, strings
        raise ResultFileError(f"{where}: {key} is not a numeric array ({exc})") from exc
    fits = values.ndim == len(shape) and all(
        want is None or want == got for want, got in zip(shape, values.shape, strict=True)
    )
    if not fits or not np.all(np.isfinite(values)):
        dims = " x ".join("n" if s is None else str(s) for s in shape)
        raise ResultFileError(
            f"{where}: {key} has shape {values.shape}: accepted finite numbers of shape {dims}"
        )
    return values


def read_rows(
    path: Path, labels: tuple[str, ...], measures: Iterable[str], hint: str
) -> list[dict[str, Any]]:
    """Evaluation rows (`results.json`, `evaluate.summarize`), each with N, K, the text
    `labels` and the `measures` and their standard deviations as finite numbers; a cell (N, K
    and the labels) given twice is refused."""
    rows = listing(load(path, hint), str(path), min_len=1)
    cells = set()
    for i, raw in enumerate(rows):
        where = f"{path}: row {i}"
        row = mapping(raw, where)
        cell: tuple[Any, ...] = tuple(text(row, key, where) for key in labels)
        cell += (integer(row, "n_auvs", where, 1), integer(row, "n_nodes", where, 1))
        for key in measures:
            number(row, key, where)
            number(row, key + "_std", where, low=0.0)
        if cell in cells:
            raise ResultFileError(
                f"{where} repeats the cell {cell}: accepted one row per ({', '.join(labels)}, N, K)"
            )
        cells.add(cell)
    return rows


def read_episodes(
    path: Path, labels: tuple[str, ...], measures: Iterable[str], hint: str
) -> list[dict[str, Any]]:
    """Episode rows (`episodes.json`, `evaluate.evaluate`), each with N, K, the text `labels`,
    its episode `seed`, its `training_seed` (an integer, null or absent: a baseline, or results
    written before training seeds) and the `measures` as finite numbers."""
    rows = listing(load(path, hint), str(path), min_len=1)
    for i, raw in enumerate(rows):
        where = f"{path}: episode {i}"
        row = mapping(raw, where)
        for key in labels:
            text(row, key, where)
        integer(row, "n_auvs", where, 1)
        integer(row, "n_nodes", where, 1)
        integer(row, "seed", where)
        if row.get("training_seed") is not None:
            integer(row, "training_seed", where)
        numbers(row, measures, where)
    return rows
