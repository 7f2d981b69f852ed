"""The config reference, made from the config's own declarations: every field of every
section with its default, unit (from its name), what its checks accept and its docstring.

`iout-mj config --dump` prints it as commented YAML (a config file to start from);
`docs/config.md` is its Markdown form (a test keeps the file current).
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import itertools
import json
import types
import typing
from dataclasses import dataclass
from typing import Any

from iout_mj import config as config_module
from iout_mj import schema
from iout_mj.config import Config

UNITS = (
    ("_nspm2", "N s^2/m^2"),
    ("_kgpm3", "kg/m^3"),
    ("_m2", "m^2"),
    ("_mps", "m/s"),
    ("_khz", "kHz"),
    ("_hz", "Hz"),
    ("_bps", "bit/s"),
    ("_degc", "deg C"),
    ("_deg", "deg"),
    ("_ppt", "ppt"),
    ("_bits", "bit"),
    ("_rad", "rad"),
    ("_ohm", "ohm"),
    ("_db", "dB"),
    ("_j", "J"),
    ("_w", "W"),
    ("_s", "s"),
    ("_m", "m"),
)
"""Units by the suffix of a field's name (the house style puts the unit in every name)."""


@dataclass(frozen=True)
class FieldDoc:
    section: str
    name: str
    default: Any
    unit: str
    accepted: tuple[str, ...]
    doc: str


def unit(name: str) -> str:
    return next((u for suffix, u in UNITS if name.endswith(suffix)), "")


def _docstrings(cls: type) -> dict[str, str]:
    """The attribute docstrings of a dataclass (the string under each field)."""
    tree = ast.parse(inspect.getsource(cls))
    body = tree.body[0].body  # type: ignore[attr-defined]
    docs = {}
    for stmt, after in itertools.pairwise(body):
        if (
            isinstance(stmt, ast.AnnAssign)
            and isinstance(stmt.target, ast.Name)
            and isinstance(after, ast.Expr)
            and isinstance(after.value, ast.Constant)
            and isinstance(after.value.value, str)
        ):
            docs[stmt.target.id] = " ".join(after.value.value.split())
    return docs


def _accepted(owner: str, name: str, section: str) -> tuple[str, ...]:
    keys = (f"{owner}.{name}", f"Config.{section}.{name}")
    texts = [t for key in keys for t in schema.ACCEPTED.get(key, {}) if t != "finite numbers only"]
    return tuple(dict.fromkeys(texts))


def fields(cfg: Config | None = None) -> list[FieldDoc]:
    """Every field of every section, with the values of `cfg` (default: the paper's)."""
    schema.ACCEPTED.clear()
    checked = Config()  # runs every check once: each notes what it accepts
    cfg = cfg or checked
    rows = []
    for section in dataclasses.fields(Config):
        part = getattr(cfg, section.name)
        cls = type(part)
        docs = {**_docstrings(cls), **_weights_docs(cls)}
        for f in dataclasses.fields(part):
            value = getattr(part, f.name)
            if dataclasses.is_dataclass(value):  # reward.weights: one row per weight
                for w in dataclasses.fields(value):
                    rows.append(
                        FieldDoc(
                            f"{section.name}.{f.name}",
                            w.name,
                            getattr(value, w.name),
                            "",
                            _accepted(type(value).__name__, w.name, section.name),
                            docs.get(w.name, ""),
                        )
                    )
                continue
            rows.append(
                FieldDoc(
                    section.name,
                    f.name,
                    value,
                    unit(f.name),
                    _accepted(cls.__name__, f.name, section.name),
                    docs.get(f.name, ""),
                )
            )
    return rows


def training_fields() -> list[FieldDoc]:
    """Every key of a training config (`iout-mj train`, `train-marl`) and of its phases and
    imitation, with its default; what its checks accept, else its type. Its env config is
    the env reference's (`env:`)."""
    from iout_mj.training.config import ImitationConfig, PhaseConfig, TrainConfig
    from iout_mj.training.marl import MarlConfig, MarlPhase

    schema.ACCEPTED.clear()
    sections: list[tuple[str, Any]] = [
        ("train", TrainConfig(imitation=ImitationConfig())),
        ("train: phases[]", PhaseConfig()),
        ("train: imitation", ImitationConfig()),
        ("train-marl", MarlConfig()),
        ("train-marl: phases[]", MarlPhase()),
    ]
    rows = []
    for section, instance in sections:
        cls: Any = type(instance)
        docs, hints = _docstrings(cls), schema.field_types(cls)
        for f in dataclasses.fields(cls):
            if f.name in ("env", "phases", "imitation"):
                continue  # sections of their own
            accepted = _accepted(cls.__name__, f.name, section) or (_type_text(hints[f.name]),)
            default = getattr(instance, f.name)  # (the instances hold the defaults)
            rows.append(
                FieldDoc(section, f.name, default, unit(f.name), accepted, docs.get(f.name, ""))
            )
    return rows


def _type_text(tp: Any) -> str:
    """What a field's annotation accepts, in words (for keys no range check covers)."""
    args = typing.get_args(tp)
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        return _type_text(next(a for a in args if a is not type(None))) + ", or null"
    if typing.get_origin(tp) is tuple:
        item = _type_text(args[0]).removeprefix("a ").removeprefix("an ")
        count = "" if args[-1] is Ellipsis else f"{len(args)} "
        return f"a list of {count}{item}s"
    return {int: "an integer", float: "a number", str: "a string", bool: "true or false"}[tp]


def _weights_docs(cls: type) -> dict[str, str]:
    for f in dataclasses.fields(cls):
        if f.name == "weights":
            return _docstrings(config_module.RewardWeights)
    return {}


def _plain(value: Any) -> str:
    """A default as YAML reads it back (JSON is YAML): null, true, [1.0, 2.0], "flat"."""
    return json.dumps(schema.to_plain(value))


def dump_yaml(cfg: Config | None = None) -> str:
    """The whole config as YAML, each field commented with its unit, range and meaning."""
    lines = [
        "# iout-mj env config: every field with its default (the paper's values), unit and what",
        "# it accepts. Keep only the keys you change; the rest stay at their defaults.",
    ]
    current = None
    for row in fields(cfg):
        path = row.section.split(".")
        if row.section != current:
            for depth, part in enumerate(path):
                if current is None or current.split(".")[: depth + 1] != path[: depth + 1]:
                    lines.append("  " * depth + f"{part}:")
            current = row.section
        indent = "  " * len(path)
        notes = "; ".join(n for n in (row.unit, *row.accepted, row.doc) if n)
        lines.append(
            f"{indent}{row.name}: {_plain(row.default)}" + (f"  # {notes}" if notes else "")
        )
    return "\n".join(lines) + "\n"


def markdown() -> str:
    """The config reference as Markdown (docs/config.md)."""
    out = [
        "# Config reference",
        "",
        "Generated from the config's own declarations by `iout-mj config --markdown` (a test",
        "keeps this file current). Every key is optional: a YAML or JSON file (`--config`,",
        "`config=`) sets only what it changes. `iout-mj config --dump` prints the same as a",
        "commented YAML file to start from.",
    ]
    out += _tables(fields())
    out += [
        "",
        "# Training config reference",
        "",
        "The keys of a training config (`iout-mj train CONFIG`, `iout-mj train-marl CONFIG`;",
        "`training/configs/` holds the recipes). Every key is optional; `env:` is an env config",
        "as above (its keys merge into the defaults), `base:` names a config this one varies",
        "(a path from its own folder; mappings merge key by key, lists and values replace);",
        "`phases:` is a list of the `phases[]` tables below, `imitation:` (DAgger from a planner",
        "before PPO; null: none) the `imitation` table, for `train-marl` too, with `node_range`",
        "null there.",
    ]
    out += _tables(training_fields())
    return "\n".join(out) + "\n"


def _tables(rows: list[FieldDoc]) -> list[str]:
    """One Markdown table per section of `rows`."""
    out: list[str] = []
    current = None
    for row in rows:
        if row.section != current:
            out += ["", f"## `{row.section}`", "", "| key | default | unit | accepted | meaning |"]
            out.append("| --- | --- | --- | --- | --- |")
            current = row.section
        accepted = "; ".join(row.accepted).replace("|", "\\|")
        out.append(
            f"| `{row.name}` | `{_plain(row.default)}` | {row.unit} | {accepted} | "
            f"{row.doc.replace('|', '/')} |"
        )
    return out
