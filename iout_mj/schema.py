"""Typed frozen dataclasses from plain data: checks, conversion and YAML/JSON files.

Every config of the project (the env's `Config`, training's `TrainConfig`) is built here, so
all of them report an unknown key, a wrong type or an invalid value the same way.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import types
import typing
from pathlib import Path
from typing import Any

import yaml

MAX_FILE_BYTES = 1 << 20
"""Config files are small; a larger one is refused unread."""
MAX_ALIASES = 64
"""YAML aliases a config file may use (an alias bomb expands a few hundred bytes into GBs)."""
MAX_SHOWN = 120
"""Characters of a value an error message shows."""


class ConfigError(ValueError):
    """A configuration value, key or file is invalid; the message says what is accepted."""


def shown(value: Any) -> str:
    """`repr(value)`, cut to MAX_SHOWN characters (error messages stay small)."""
    text = repr(value)
    return text if len(text) <= MAX_SHOWN else text[: MAX_SHOWN - 15] + f"... ({len(text)} chars)"


def require(ok: bool, name: str, value: Any, accepted: str) -> None:
    if not ok:
        raise ConfigError(f"{name}={shown(value)} is invalid: accepted {accepted}")


def check_finite(obj: Any) -> None:
    """Every number of a dataclass (in tuples too) is finite: NaN and inf are never settings."""
    for f in dataclasses.fields(obj):
        for value in _numbers(getattr(obj, f.name)):
            require(math.isfinite(value), f.name, getattr(obj, f.name), "finite numbers only")


def _numbers(value: Any) -> list[float]:
    if isinstance(value, bool):
        return []
    if isinstance(value, (int, float)):
        return [float(value)]
    if isinstance(value, (tuple, list)):
        return [x for v in value for x in _numbers(v)]
    return []


def finite_at_least(obj: Any, low: float, *names: str) -> None:
    for name in names:
        value = getattr(obj, name)
        require(math.isfinite(value) and value >= low, name, value, f"a finite number >= {low:g}")


def positive(obj: Any, *names: str) -> None:
    for name in names:
        value = getattr(obj, name)
        require(math.isfinite(value) and value > 0, name, value, "a finite number > 0")


def fraction(obj: Any, *names: str) -> None:
    for name in names:
        value = getattr(obj, name)
        require(math.isfinite(value) and 0 < value <= 1, name, value, "a number in (0, 1]")


def _convert(tp: Any, value: Any, name: str) -> Any:
    """Check `value` against the annotation `tp` and convert lists to tuples."""
    origin = typing.get_origin(tp)
    if dataclasses.is_dataclass(tp):
        return build_dataclass(tp, value, name)
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{name}={shown(value)} has the wrong type: accepted a list")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(args[0], v, f"{name}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise ConfigError(
                f"{name}={shown(value)} is invalid: accepted a list of {len(args)} values"
            )
        return tuple(
            _convert(a, v, f"{name}[{i}]") for i, (a, v) in enumerate(zip(args, value, strict=True))
        )
    if origin in (typing.Union, types.UnionType):
        present = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(present) != 1 or len(typing.get_args(tp)) != 2:
            raise ConfigError(f"{name}: only optional (X | None) unions are supported in configs")
        return None if value is None else _convert(present[0], value, name)
    if tp is float:
        if isinstance(value, str) and _is_number_text(value):
            raise ConfigError(
                f"{name}={shown(value)} was read as text: write it as a number, e.g. "
                f"{float(value):g}"
            )
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{name}={shown(value)} has the wrong type: accepted a number")
        if not math.isfinite(value):
            raise ConfigError(f"{name}={value} is invalid: accepted a finite number")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{name}={shown(value)} has the wrong type: accepted an integer")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{name}={shown(value)} has the wrong type: accepted a string")
        return value
    raise ConfigError(f"{name}: unsupported field type {tp}")


def build_dataclass(cls: Any, data: Any, name: str) -> Any:
    """An instance of the frozen dataclass `cls` from a mapping, checked key by key (unknown
    keys, wrong types and invalid values raise `ConfigError` naming the field)."""
    if isinstance(data, cls):
        return data
    if not isinstance(data, dict):
        raise ConfigError(f"{name}={shown(data)} has the wrong type: accepted a mapping")
    hints = typing.get_type_hints(cls)
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ConfigError(f"{name}: unknown key(s) {unknown}; accepted keys {sorted(known)}")
    kwargs = {k: _convert(hints[k], v, f"{name}.{k}") for k, v in data.items()}
    return cls(**kwargs)


def _is_number_text(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


class _Loader(yaml.SafeLoader):
    """PyYAML's safe loader, with YAML 1.2 floats (`2e6` is a number, as in JSON) and a cap on
    aliases."""

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            self.aliases_seen = getattr(self, "aliases_seen", 0) + 1
            if self.aliases_seen > MAX_ALIASES:
                raise ConfigError(f"more than {MAX_ALIASES} YAML aliases: refused")
        return super().compose_node(parent, index)


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


def load_mapping(path: str | Path, what: str) -> dict[str, Any]:
    """The mapping in a YAML or JSON file; an empty, unreadable, oversized or non-mapping file
    is an error that names it."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{what} {path} does not exist")
    if path.stat().st_size > MAX_FILE_BYTES:
        raise ConfigError(f"{what} {path} is larger than {MAX_FILE_BYTES} bytes")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{what} {path} is not UTF-8 text: {exc}") from exc
    try:
        data = json.loads(text) if path.suffix == ".json" else yaml.load(text, Loader=_Loader)
    except (json.JSONDecodeError, yaml.YAMLError) as exc:
        raise ConfigError(f"{what} {path} is not valid YAML/JSON: {shown(str(exc))}") from exc
    if data is None:
        raise ConfigError(f"{what} {path} is empty: accepted a mapping of settings")
    if not isinstance(data, dict):
        raise ConfigError(f"{what} {path} holds a {type(data).__name__}; accepted a mapping")
    return data


def to_plain(value: Any) -> Any:
    """Nested dicts, lists and scalars (tuples become lists), for YAML and JSON."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        value = dataclasses.asdict(value)
    if isinstance(value, dict):
        return {k: to_plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_plain(v) for v in value]
    return value
