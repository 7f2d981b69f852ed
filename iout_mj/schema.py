"""Typed frozen dataclasses from plain data: checks, conversion and YAML/JSON files.

Every config of the project (the env's `Config`, training's `TrainConfig`) is built here, so
all of them report an unknown key, a wrong type or an invalid value the same way.
"""

from __future__ import annotations

import dataclasses
import json
import math
import types
import typing
from pathlib import Path
from typing import Any

import yaml


class ConfigError(ValueError):
    """A configuration value, key or file is invalid; the message says what is accepted."""


def require(ok: bool, name: str, value: Any, accepted: str) -> None:
    if not ok:
        raise ConfigError(f"{name}={value!r} is invalid: accepted {accepted}")


def positive(obj: Any, *names: str) -> None:
    for name in names:
        value = getattr(obj, name)
        require(math.isfinite(value) and value > 0, name, value, "a finite number > 0")


def fraction(obj: Any, *names: str) -> None:
    for name in names:
        value = getattr(obj, name)
        require(0 < value <= 1, name, value, "a number in (0, 1]")


def _convert(tp: Any, value: Any, name: str) -> Any:
    """Check `value` against the annotation `tp` and convert lists to tuples."""
    origin = typing.get_origin(tp)
    if dataclasses.is_dataclass(tp):
        return build_dataclass(tp, value, name)
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{name}={value!r} has the wrong type: accepted a list")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(args[0], v, f"{name}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise ConfigError(f"{name}={value!r} is invalid: accepted a list of {len(args)} values")
        return tuple(
            _convert(a, v, f"{name}[{i}]") for i, (a, v) in enumerate(zip(args, value, strict=True))
        )
    if origin in (typing.Union, types.UnionType):
        raise ConfigError(f"{name}: union types are not supported in configs")
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{name}={value!r} has the wrong type: accepted a number")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{name}={value!r} has the wrong type: accepted an integer")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{name}={value!r} has the wrong type: accepted a string")
        return value
    raise ConfigError(f"{name}: unsupported field type {tp}")


def build_dataclass(cls: Any, data: Any, name: str) -> Any:
    """An instance of the frozen dataclass `cls` from a mapping, checked key by key (unknown
    keys, wrong types and invalid values raise `ConfigError` naming the field)."""
    if isinstance(data, cls):
        return data
    if not isinstance(data, dict):
        raise ConfigError(f"{name}={data!r} has the wrong type: accepted a mapping")
    hints = typing.get_type_hints(cls)
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ConfigError(f"{name}: unknown key(s) {unknown}; accepted keys {sorted(known)}")
    kwargs = {k: _convert(hints[k], v, f"{name}.{k}") for k, v in data.items()}
    return cls(**kwargs)


def load_mapping(path: str | Path, what: str) -> dict[str, Any]:
    """The mapping in a YAML or JSON file (an empty file is an empty mapping)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{what} {path} does not exist")
    text = path.read_text()
    try:
        data = json.loads(text) if path.suffix == ".json" else yaml.safe_load(text)
    except (json.JSONDecodeError, yaml.YAMLError) as exc:
        raise ConfigError(f"{what} {path} is not valid YAML/JSON: {exc}") from exc
    data = {} if data is None else data
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
