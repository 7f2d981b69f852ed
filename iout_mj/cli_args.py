"""Argument types and checks of the command line: every bad value says what is accepted, and
every output place is checked writable before any work starts."""

from __future__ import annotations

import argparse
import dataclasses
import math
import tempfile
from pathlib import Path
from typing import Any

from iout_mj.config import Config
from iout_mj.scenarios import fixed_config
from iout_mj.schema import ConfigError, load_mapping


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


def _file_scenario(config: str) -> dict[str, Any]:
    """The scenario keys a config file sets itself (not the defaults it inherits)."""
    return load_mapping(config, "config file").get("scenario") or {}


def evaluation_config(config: str | None) -> Config:
    """The env config of an evaluation: N and K come from the flags, so a file that sets them
    is refused rather than silently overridden."""
    if config is None:
        return Config()
    scenario = _file_scenario(config)
    fixed = sorted({"n_auvs", "nodes_m"} & set(scenario))
    if fixed:
        raise ConfigError(
            f"{config} sets scenario {', '.join(fixed)}: evaluate takes N and K from --n-auvs "
            "and --nodes (and the layout from --layout); remove them from the file"
        )
    return Config.load(config)


def scenario_from_flags(
    config: str | None, n_auvs: int | None, n_nodes: int | None, layout: str = "paper"
) -> Config:
    """The mission's config: a flag applies only when given; a flag that contradicts what the
    config file sets is an error naming both. With layout "random" the nodes are drawn per
    episode (the file's nodes_m is then refused)."""
    if layout == "random":
        base = evaluation_config(config)
        n = 2 if n_auvs is None else n_auvs
        k = base.scenario.n_nodes if n_nodes is None else n_nodes
        return fixed_config(n, k, base)  # N and K; the env draws the nodes every episode
    if config is None:
        return fixed_config(2 if n_auvs is None else n_auvs, 7 if n_nodes is None else n_nodes)
    scenario = _file_scenario(config)
    base = Config.load(config)
    sets_n, sets_k = "n_auvs" in scenario, "nodes_m" in scenario
    for flag, given, sets, has in (
        ("--n-auvs", n_auvs, sets_n, base.scenario.n_auvs),
        ("--nodes", n_nodes, sets_k, base.scenario.n_nodes),
    ):
        if given is not None and sets and given != has:
            raise ConfigError(
                f"{flag} {given} contradicts {config}, which sets {has}: give one or the other"
            )
    if sets_k:  # the file's own nodes; N from the flag if the file leaves it open
        n = base.scenario.n_auvs if sets_n or n_auvs is None else n_auvs
        return base.replace(scenario=dataclasses.replace(base.scenario, n_auvs=n))
    n = base.scenario.n_auvs if n_auvs is None else n_auvs
    k = base.scenario.n_nodes if n_nodes is None else n_nodes
    return fixed_config(n, k, base)
