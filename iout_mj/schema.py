"""Typed frozen dataclasses from plain data: checks, conversion and YAML/JSON files.

Every config of the project (the env's `Config`, training's `TrainConfig`) is built here, so
all of them report an unknown key, a wrong type or an invalid value the same way.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import os
import re
import stat
import types
import typing
from pathlib import Path
from typing import Any

import yaml

from iout_mj.errors import IoutError

MAX_FILE_BYTES = 1 << 20
"""Config files are small; a larger one is refused unread."""
MAX_ALIASES = 64
"""YAML aliases a config file may use (an alias bomb expands a few hundred bytes into GBs)."""
MAX_DEPTH = 32
"""Nesting of lists and mappings a config file may use (the deepest config is 4 levels)."""
MAX_ENTRIES = 100_000
"""Values a config file may hold, counting each use of a YAML alias in full."""
MAX_SHOWN = 120
"""Characters of a value an error message shows."""


class ConfigError(IoutError, ValueError):
    """A configuration value, key or file is invalid; the message says what is accepted."""


def shown(value: Any) -> str:
    """`repr(value)`, cut to MAX_SHOWN characters (error messages stay small)."""
    text = repr(value)
    return text if len(text) <= MAX_SHOWN else text[: MAX_SHOWN - 15] + f"... ({len(text)} chars)"


ACCEPTED: dict[str, dict[str, None]] = {}
"""What each checked field accepts, keyed "Owner.field", as its checks state it: every check
notes its text here, so the config reference (`config_reference`) is made from the checks
themselves. A few texts per field at most (some quote the values they were checked with)."""
_owner = [""]


def require(ok: bool, name: str, value: Any, accepted: str) -> None:
    texts = ACCEPTED.setdefault(f"{_owner[0]}.{name}", {})
    if len(texts) < 4:
        texts[accepted] = None
    if not ok:
        raise ConfigError(f"{name}={shown(value)} is invalid: accepted {accepted}")


def one_of(obj: Any, name: str, accepted: Any) -> None:
    """`obj.name` is one of `accepted` (named in the message, quoted)."""
    value = getattr(obj, name)
    require(value in accepted, name, value, "one of " + ", ".join(repr(a) for a in accepted))


def check_finite(obj: Any) -> None:
    """Every number of a dataclass (in tuples too) is finite: NaN and inf are never settings.
    (Called first by every config's checks: the checks that follow note what they accept
    under its class's name.)"""
    _owner[0] = type(obj).__name__
    for f in dataclasses.fields(obj):
        for value in _numbers(getattr(obj, f.name)):
            require(math.isfinite(value), f.name, getattr(obj, f.name), "finite numbers only")


def _numbers(value: Any) -> list[float]:
    if isinstance(value, float):
        return [value]
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


def _number(value: float) -> str:
    return f"{value:g}"


def in_range(
    obj: Any, name: str, low: float, high: float, why: str = "", low_open: bool = False
) -> None:
    """`obj.name` lies in [low, high] ((low, high] with `low_open`); `why` says where the
    bounds come from when that is not obvious."""
    value = getattr(obj, name)
    ok = (low < value if low_open else low <= value) and value <= high
    kind = "an integer" if isinstance(value, int) else "a number"
    bracket = "(" if low_open else "["
    reason = f" ({why})" if why else ""
    require(ok, name, value, f"{kind} in {bracket}{_number(low)}, {_number(high)}]{reason}")


def fraction(obj: Any, *names: str) -> None:
    for name in names:
        value = getattr(obj, name)
        require(math.isfinite(value) and 0 < value <= 1, name, value, "a number in (0, 1]")


def convert(tp: Any, value: Any, name: str) -> Any:
    """Check `value` against the annotation `tp` and convert lists to tuples."""
    origin = typing.get_origin(tp)
    if dataclasses.is_dataclass(tp):
        from_dict = getattr(tp, "from_dict", None)  # a section that completes its own data
        if from_dict is not None and isinstance(value, dict):
            return from_dict(value, name)
        return build_dataclass(tp, value, name)
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{name}={shown(value)} has the wrong type: accepted a list")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(convert(args[0], v, f"{name}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise ConfigError(
                f"{name}={shown(value)} is invalid: accepted a list of {len(args)} values"
            )
        return tuple(
            convert(a, v, f"{name}[{i}]") for i, (a, v) in enumerate(zip(args, value, strict=True))
        )
    if origin in (typing.Union, types.UnionType):
        present = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(present) != 1 or len(typing.get_args(tp)) != 2:
            raise ConfigError(f"{name}: only optional (X | None) unions are supported in configs")
        return None if value is None else convert(present[0], value, name)
    if tp is float:
        if isinstance(value, str) and _is_number_text(value):
            raise ConfigError(
                f"{name}={shown(value)} was read as text: write it as a number, e.g. "
                f"{float(value):g}"
            )
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{name}={shown(value)} has the wrong type: accepted a number")
        try:
            number = float(value)
        except OverflowError:
            number = math.inf
        if not math.isfinite(number):
            raise ConfigError(f"{name}={shown(value)} is invalid: accepted a finite number")
        return number
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{name}={shown(value)} has the wrong type: accepted an integer")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{name}={shown(value)} has the wrong type: accepted a string")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{name}={shown(value)} has the wrong type: accepted true or false")
        return value
    raise ConfigError(f"{name}: unsupported field type {tp}")


@functools.cache
def field_types(cls: Any) -> dict[str, Any]:
    """The resolved annotations of a dataclass (resolving them is the slow part of a check)."""
    return typing.get_type_hints(cls)


def check_types(config: Any) -> None:
    """A config built in code is checked as one read from a file: every field against its
    annotation (integers, numbers, strings, booleans, lists, sections), before any range check;
    lists become tuples and mappings sections, as when read (`schema.build_dataclass`)."""
    cls: Any = type(config)
    hints = field_types(cls)
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        converted = convert(hints[f.name], value, f.name)
        if converted is not value:
            object.__setattr__(config, f.name, converted)  # frozen: set once, while built
    _owner[0] = cls.__name__  # (after its sections': the checks that follow note under it)


def build_dataclass(cls: Any, data: Any, name: str) -> Any:
    """An instance of the frozen dataclass `cls` from a mapping, checked key by key (unknown
    keys, wrong types and invalid values raise `ConfigError` naming the field)."""
    if isinstance(data, cls):
        return data
    if not isinstance(data, dict):
        raise ConfigError(f"{name}={shown(data)} has the wrong type: accepted a mapping")
    hints = field_types(cls)
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(shown(k) for k in set(data) - known)
    if unknown:
        raise ConfigError(f"{name}: unknown key(s) {unknown}; accepted keys {sorted(known)}")
    kwargs = {k: convert(hints[k], v, f"{name}.{k}") for k, v in data.items()}
    try:
        return cls(**kwargs)
    except ConfigError as exc:  # a check of the dataclass: say where the field is
        raise ConfigError(f"{name}.{exc}") from None


def _is_number_text(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


class _Loader(yaml.SafeLoader):
    """PyYAML's safe loader, with YAML 1.2 floats (`2e6` is a number, as in JSON), a cap on
    aliases and on nesting (checked while composing, before the composer's recursion can go
    deep), and duplicate keys refused."""

    aliases_seen = 0
    depth = 0

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            self.aliases_seen += 1
            if self.aliases_seen > MAX_ALIASES:
                raise ConfigError(f"more than {MAX_ALIASES} YAML aliases: refused")
        self.depth += 1
        if self.depth > MAX_DEPTH:
            raise ConfigError(f"lists and mappings nested deeper than {MAX_DEPTH}: refused")
        try:
            return super().compose_node(parent, index)
        finally:
            self.depth -= 1

    def construct_mapping(self, node: Any, deep: bool = False) -> Any:
        if isinstance(node, yaml.MappingNode):
            seen: set[Any] = set()
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue  # `<<: *defaults` may be overridden by the mapping's own keys
                key = self.construct_object(key_node, deep=True)
                if isinstance(key, typing.Hashable):
                    if key in seen:
                        raise ConfigError(
                            f"key {shown(key)} appears twice in one mapping "
                            f"(line {key_node.start_mark.line + 1}): accepted each key once"
                        )
                    seen.add(key)
        return super().construct_mapping(node, deep=deep)


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


def _json_pairs(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object whose keys are all distinct."""
    data: dict[str, Any] = {}
    for key, value in pairs:
        if key in data:
            raise ConfigError(f"key {shown(key)} appears twice in one object: accepted each once")
        data[key] = value
    return data


_JSON_TOKEN = re.compile(r'[\[\]{}"\\]')


def _json_depth(text: str) -> int:
    """The deepest nesting of brackets outside strings, in one linear scan without parsing
    (json's parser recurses once per level)."""
    depth = deepest = 0
    in_string, escaped_at = False, -1
    for match in _JSON_TOKEN.finditer(text):
        i, c = match.start(), match.group()
        if i == escaped_at:
            continue
        if in_string:
            if c == "\\":
                escaped_at = i + 1
            in_string = c != '"'
        elif c == '"':
            in_string = True
        elif c in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif c in "]}":
            depth -= 1
    return deepest


def _children(value: Any) -> list[Any]:
    items = value.items() if isinstance(value, dict) else enumerate(value)
    return [v for _, v in items if isinstance(v, (dict, list))]


def _check_size(data: Any) -> None:
    """Nesting at most MAX_DEPTH and at most MAX_ENTRIES values, counting every use of a
    shared (aliased) list or mapping; iterative and linear in the distinct containers."""
    height: dict[int, int] = {}
    entries: dict[int, int] = {}
    open_ids: set[int] = set()
    stack: list[tuple[Any, bool]] = [(data, False)] if isinstance(data, (dict, list)) else []
    while stack:
        value, closing = stack.pop()
        key = id(value)
        if closing:
            children = _children(value)
            height[key] = 1 + max((height[id(c)] for c in children), default=0)
            entries[key] = len(value) + sum(entries[id(c)] for c in children)
            open_ids.discard(key)
            if height[key] > MAX_DEPTH:
                raise ConfigError(f"lists and mappings nested deeper than {MAX_DEPTH}: refused")
            if entries[key] > MAX_ENTRIES:
                raise ConfigError(f"more than {MAX_ENTRIES} values (aliases expanded): refused")
        elif key not in height:
            if key in open_ids:
                raise ConfigError("a list or mapping that contains itself: refused")
            open_ids.add(key)
            stack.append((value, True))
            stack.extend((c, False) for c in _children(value))


_FILE_KINDS = {
    stat.S_ISDIR: "a directory",
    stat.S_ISFIFO: "a FIFO",
    stat.S_ISCHR: "a character device",
    stat.S_ISBLK: "a block device",
    stat.S_ISSOCK: "a socket",
}


def read_bytes(path: Path, what: str, max_bytes: int = MAX_FILE_BYTES) -> bytes:
    """The bytes of a regular file of at most `max_bytes`; anything else (a directory, FIFO,
    device, a /proc file that yields more, an unreadable file) is a ConfigError naming it.

    The file is opened non-blocking (a FIFO with no writer would block) and checked on the
    open descriptor, and at most `max_bytes` + 1 bytes are read (a /proc file reports size 0).
    """
    flags = os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOCTTY", 0)
    try:
        fd = os.open(path, flags)
    except FileNotFoundError:
        raise ConfigError(f"{what} {path} does not exist") from None
    except OSError as exc:
        raise ConfigError(f"{what} {path} cannot be opened: {exc.strerror or exc}") from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            kind = next((k for test, k in _FILE_KINDS.items() if test(mode)), "a special file")
            raise ConfigError(f"{what} {path} is {kind}: accepted a regular file")
        chunks: list[bytes] = []
        size = 0
        while size <= max_bytes:
            chunk = os.read(fd, max_bytes + 1 - size)
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as exc:
        raise ConfigError(f"{what} {path} cannot be read: {exc.strerror or exc}") from None
    finally:
        os.close(fd)
    if size > max_bytes:
        raise ConfigError(f"{what} {path} is larger than {max_bytes} bytes")
    return b"".join(chunks)


def _parse(text: str, suffix: str) -> Any:
    if suffix == ".json":
        if _json_depth(text) > MAX_DEPTH:
            raise ConfigError(f"lists and mappings nested deeper than {MAX_DEPTH}: refused")
        return json.loads(text, object_pairs_hook=_json_pairs)
    return yaml.load(text, Loader=_Loader)


def load_mapping(path: str | Path, what: str) -> dict[str, Any]:
    """The mapping in a YAML or JSON file; an empty, unreadable, oversized, non-regular,
    over-deep or non-mapping file, or one with a duplicated key, is an error that names it."""
    path = Path(path)
    raw = read_bytes(path, what)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{what} {path} is not UTF-8 text: {exc}") from exc
    try:
        data = _parse(text, path.suffix)
        _check_size(data)
    except ConfigError as exc:
        raise ConfigError(f"{what} {path}: {exc}") from None
    except (yaml.YAMLError, ValueError, RecursionError) as exc:  # ValueError: json, int digits
        raise ConfigError(f"{what} {path} is not valid YAML/JSON: {shown(str(exc))}") from exc
    if data is None:
        raise ConfigError(f"{what} {path} is empty: accepted a mapping of settings")
    if not isinstance(data, dict):
        raise ConfigError(f"{what} {path} holds a {type(data).__name__}; accepted a mapping")
    return data


MAX_BASES = 8
"""Configs a `base:` chain may stack (a variant of a variant of ...)."""


def overlay(base: dict[str, Any], top: dict[str, Any]) -> dict[str, Any]:
    """`base` with `top`'s keys: mappings merged key by key, anything else replaced."""
    out = dict(base)
    for key, value in top.items():
        below = out.get(key)
        if isinstance(below, dict) and isinstance(value, dict):
            value = overlay(below, value)
        out[key] = value
    return out


def load_layered(
    path: str | Path,
    what: str,
    prepare: typing.Callable[[dict[str, Any], Path], dict[str, Any]] = lambda data, _: data,
) -> dict[str, Any]:
    """The mapping in a YAML or JSON file whose optional `base:` names the file it extends
    (relative to its own folder): the base's mapping `overlay`-ed with this file's keys, up to
    MAX_BASES files deep, no file twice. `prepare(data, folder)` adjusts each file's data as
    read (its relative paths, from its own folder) before they are merged."""
    path = Path(path)
    layers: list[dict[str, Any]] = []
    seen: list[Path] = []
    while True:
        real = Path(os.path.realpath(path))  # (Path.resolve raises on a symlink loop)
        if real in seen:
            raise ConfigError(f"{what} {path} is its own base (through its bases): refused")
        if len(seen) == MAX_BASES:
            raise ConfigError(f"{what} {path}: bases stacked more than {MAX_BASES} deep: refused")
        seen.append(real)
        data = prepare(load_mapping(path, what), path.parent)
        base = data.pop("base", None)
        layers.append(data)
        if base is None:
            break
        if not isinstance(base, str) or not base.strip():
            raise ConfigError(
                f"{what} {path}: base={shown(base)} is invalid: accepted the path of the "
                "config file it extends, relative to its folder"
            )
        path = path.parent / base
    merged: dict[str, Any] = {}
    for layer in reversed(layers):
        merged = overlay(merged, layer)
    return merged


def to_plain(value: Any) -> Any:
    """Nested dicts, lists and scalars (tuples become lists), for YAML and JSON."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        value = dataclasses.asdict(value)
    if isinstance(value, dict):
        return {k: to_plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_plain(v) for v in value]
    return value
