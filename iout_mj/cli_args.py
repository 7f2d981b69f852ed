"""Argument types and checks of the command line: every bad value says what is accepted, and
every output place is checked writable before any work starts."""

from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path
from typing import Any

from iout_mj.schema import ConfigError


def _number(text: str, kind: type, what: str) -> Any:
    try:
        value = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not {what}") from None
    if isinstance(value, float) and not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not {what}")
    return value


def int_at_least(low: int) -> Any:
    """An argparse type: an integer >= low."""

    def parse(text: str) -> int:
        value = _number(text, int, f"an integer >= {low}")
        if value < low:
            raise argparse.ArgumentTypeError(f"{text} is invalid: accepted an integer >= {low}")
        return int(value)

    parse.__name__ = f"integer >= {low}"
    return parse


def int_between(low: int, high: int, what: str) -> Any:
    """An argparse type: an integer from `low` to `high` (`what` says why that high)."""

    def parse(text: str) -> int:
        accepted = f"accepted an integer from {low} to {high} ({what})"
        value = _number(text, int, accepted)
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"{text} is invalid: {accepted}")
        return int(value)

    parse.__name__ = f"integer from {low} to {high}"
    return parse


def positive_distance(text: str) -> float:
    value = _number(text, float, "a number; accepted a distance > 0 m")
    if value <= 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive distance; accepted > 0 m")
    return float(value)


def positive_seconds(text: str) -> float:
    """An argparse type: a duration > 0 s."""
    value = _number(text, float, "a number; accepted a duration > 0 s")
    if value <= 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive duration; accepted > 0 s")
    return float(value)


def writable_dir(path: Path) -> Path:
    """Create `path` if needed and prove a file can be written there (before the work)."""
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path, prefix=".write-test-"):
            pass
    except OSError as exc:
        raise ConfigError(f"cannot write to {path}: {exc.strerror or exc}") from exc
    return path
