"""Scenarios: node layouts and the one place where (config, N, K, layout, nodes, backend)
become an `EnvSpec` (`resolve`).

Every entry point (gymnasium, the VecEnvs, PettingZoo, the CLI, evaluation, training,
benchmarks) resolves its scenario here. Layouts:

- "paper": the paper's layout for K = 7 and 13, else one seeded layout per K
  (`random_layout(K, seed=K)`), the same for every policy and episode;
- "random": a new seeded layout every episode, drawn from the task RNG;
- "custom": the nodes a config sets itself (`scenario.nodes_m`) or a nodes file gives, kept
  in every episode. A keyword that contradicts them is an error naming both.

`SCENARIOS` names the scenarios the test suite runs every invariant over (`paper-k7`,
`paper-k13`, `random-k{K}`), as dm_control's `suite.ALL_TASKS`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeAlias

import numpy as np

from iout_mj.backends.registry import BACKENDS
from iout_mj.config import (
    MAX_AUVS,
    MAX_NODES,
    MIN_NODES,
    PAPER_LAYOUTS,
    Config,
    Point,
    ScenarioConfig,
    files_from_folder,
)
from iout_mj.errors import require_integer, require_seed
from iout_mj.schema import ConfigError, load_mapping, overlay, require

LAYOUTS = ("paper", "random")
"""Layouts a caller may ask for; "custom" is what a config's or a file's own nodes give."""
ConfigLike: TypeAlias = (
    "Config | EnvSpec | dict[str, Any] | str | Path | Sequence[dict[str, Any] | str | Path] | None"
)
"""An env config: an object, plain data, a YAML/JSON file, several files or mappings combined
(`combined_mapping`), or None (the paper's defaults)."""
"""What `config=` accepts everywhere: a Config, a dict, a YAML/JSON path, None (the paper's
defaults), or an `EnvSpec` that `resolve` made."""
NodesLike = Sequence[Point] | str | Path | None
"""What `nodes=` accepts: a sequence of (x, y) in metres, a CSV file of them, or None."""
MAX_NODES_FILE_BYTES = 1 << 16
"""A nodes file holds at most MAX_NODES rows: a larger one is refused unread."""


@dataclass(frozen=True)
class Scenario:
    """A named scenario: the env keywords `gymnasium.make` takes for it."""

    n_nodes: int
    layout: str

    def env_kwargs(self, n_auvs: int) -> dict[str, Any]:
        return {"n_auvs": n_auvs, "n_nodes": self.n_nodes, "layout": self.layout}


SCENARIOS: dict[str, Scenario] = {
    "paper-k7": Scenario(7, "paper"),
    "paper-k13": Scenario(13, "paper"),
    **{f"random-k{k}": Scenario(k, "random") for k in (2, 3, 5, 9, 20, 30)},
}


def random_layout(
    n_nodes: int,
    seed: int | None,
    scenario: ScenarioConfig | None = None,
    min_spacing_m: float = 80.0,
    margin_m: float = 50.0,
) -> tuple[Point, ...]:
    """Seeded node layout inside the area, `min_spacing_m` apart and outside the dock zone."""
    n_nodes = require_integer(n_nodes, "n_nodes", MIN_NODES, MAX_NODES, ConfigError)
    seed = require_seed(seed, "seed", allow_none=True, error=ConfigError)
    sc = scenario or ScenarioConfig()
    rng = np.random.default_rng(seed)
    lo = np.array([margin_m, margin_m])
    hi = np.asarray(sc.area_m) - margin_m
    dock = np.asarray(sc.dock_center_m)
    points: list[np.ndarray] = []
    for _ in range(100_000):
        p = rng.uniform(lo, hi)
        if np.linalg.norm(p - dock) < sc.dock_radius_m + min_spacing_m:
            continue
        if all(np.linalg.norm(p - q) >= min_spacing_m for q in points):
            points.append(p)
            if len(points) == n_nodes:
                return tuple((round(float(x), 1), round(float(y), 1)) for x, y in points)
    raise ConfigError(f"cannot place {n_nodes} nodes {min_spacing_m} m apart in area {sc.area_m}")


def make_config(
    n_auvs: int = 2,
    n_nodes: int = 7,
    layout: str = "paper",
    seed: int = 0,
    base: Config | None = None,
) -> Config:
    """A config with `n_auvs` AUVs and a node layout.

    Args:
        n_auvs: number of AUVs (1 to 4).
        n_nodes: number of nodes (2 to 30).
        layout: "paper" (the paper's 7- or 13-node layout) or "random" (seeded by `seed`).
        seed: seed of a random layout.
        base: config whose other sections are kept (defaults: the paper's).
    """
    n_auvs, n_nodes = _counts(n_auvs, n_nodes)
    base = base or Config()
    if layout == "paper":
        require(
            n_nodes in PAPER_LAYOUTS,
            "n_nodes",
            n_nodes,
            f"{sorted(PAPER_LAYOUTS)} with layout='paper' (use layout='random' otherwise)",
        )
        nodes = PAPER_LAYOUTS[n_nodes]
    elif layout == "random":
        nodes = random_layout(n_nodes, seed, base.scenario)
    else:
        raise ConfigError(f"layout={layout!r} is invalid: accepted one of {LAYOUTS}")
    nodes = tuple((float(x), float(y)) for x, y in nodes)
    scenario = dataclasses.replace(base.scenario, n_auvs=n_auvs, nodes_m=nodes)
    return base.replace(scenario=scenario)


def _counts(n_auvs: Any, n_nodes: Any) -> tuple[Any, Any]:
    """N and K checked as integers in the config's ranges (None: left to the config)."""
    if n_auvs is not None:
        n_auvs = require_integer(n_auvs, "n_auvs", 1, MAX_AUVS, ConfigError)
    if n_nodes is not None:
        n_nodes = require_integer(n_nodes, "n_nodes", MIN_NODES, MAX_NODES, ConfigError)
    return n_auvs, n_nodes


def load_config(config: ConfigLike) -> Config:
    """A Config from a Config, a dict, a YAML/JSON path, or None (the paper's defaults)."""
    if config is None:
        return Config()
    if isinstance(config, Config):
        return config
    if isinstance(config, EnvSpec):
        return config.config
    if isinstance(config, dict):
        return Config.from_dict(config)
    if isinstance(config, (str, Path)):
        return Config.load(config)
    if isinstance(config, (list, tuple)):
        return Config.from_dict(combined_mapping(config))
    raise ConfigError(
        f"config={config!r:.80}: accepted a Config, a dict, a file path, a list of files or "
        "dicts, or None"
    )


def combined_mapping(configs: Sequence[Any]) -> dict[str, Any]:
    """The plain data of several env configs (files or mappings) in order, a later one's keys
    overriding an earlier one's section by section: `realistic-channel.yaml` then `wenz.yaml`
    is the realistic channel with Wenz noise."""
    merged: dict[str, Any] = {}
    for i, config in enumerate(configs):
        if isinstance(config, (str, Path)):
            data = files_from_folder(load_mapping(config, "config file"), Path(config).parent)
        elif isinstance(config, dict):
            data = config
        else:
            raise ConfigError(
                f"config[{i}]={config!r:.80}: accepted a file path or a dict in a list of configs"
            )
        merged = overlay(merged, data)
    return merged


def fixed_config(n_auvs: int, n_nodes: int, base: ConfigLike = None) -> Config:
    """The paper's layout for K = 7 and 13, else the seeded layout `random_layout(K, seed=K)`:
    one fixed layout per K (evaluation, missions, benchmarks)."""
    layout = "paper" if n_nodes in PAPER_LAYOUTS else "random"
    return make_config(n_auvs, n_nodes, layout, seed=n_nodes, base=load_config(base))


@dataclass(frozen=True)
class EnvSpec:
    """What an environment is: its resolved config (N and the nodes applied), its layout and
    its backend. Every env, VecEnv, command and training run is built from one."""

    config: Config
    layout: str
    """"paper", "random" (new nodes every episode) or "custom" (the config's own nodes)."""
    backend: str

    @property
    def n_auvs(self) -> int:
        return self.config.scenario.n_auvs

    @property
    def n_nodes(self) -> int:
        return self.config.scenario.n_nodes

    @property
    def random_per_episode(self) -> bool:
        return self.layout == "random"


def given_keys(config: ConfigLike) -> set[str]:
    """The scenario keys (`n_auvs`, `nodes_m`, ...) a config sets itself."""
    if isinstance(config, EnvSpec):
        return {"n_auvs", "nodes_m"}
    return _given(config)[1]


def _given(config: ConfigLike) -> tuple[Config, set[str]]:
    """The config and the scenario keys its source sets itself (a Config object: those that
    differ from the defaults)."""
    if isinstance(config, (str, Path)):
        return _given(combined_mapping([config]))
    if isinstance(config, dict):
        return Config.from_dict(config), set(config.get("scenario") or {})
    if isinstance(config, (list, tuple)):
        return _given(combined_mapping(config))
    cfg = load_config(config)
    default = ScenarioConfig()
    return cfg, {
        k for k in ("n_auvs", "nodes_m") if getattr(cfg.scenario, k) != getattr(default, k)
    }


def read_nodes(nodes: NodesLike) -> tuple[Point, ...] | None:
    """Node positions (x, y) from a sequence or a CSV file (`read_layout`; a depth column is
    read by `read_layout`)."""
    layout = read_layout(nodes)
    return None if layout is None else layout[0]


def read_layout(nodes: NodesLike) -> tuple[tuple[Point, ...], tuple[float, ...]] | None:
    """Node positions and seabed depths from a sequence or a CSV file: one `x, y` or
    `x, y, z` per row in metres (z: the node's seabed depth, positive down; every row alike),
    a header row and `#` comments allowed. The depths are () where no row gives one."""
    if nodes is None:
        return None
    given: Any = _read_rows(Path(nodes)) if isinstance(nodes, (str, Path)) else nodes
    accepted = "(x, y) or (x, y, z) in metres, z the seabed depth below the surface (>= 0)"
    try:
        rows = [tuple(float(v) for v in row) for row in given]
    except (TypeError, ValueError):
        raise ConfigError(f"nodes={nodes!r} is invalid: accepted a list of {accepted}") from None
    widths = {len(row) for row in rows}
    if not widths <= {2, 3} or len(widths) > 1:
        raise ConfigError(
            f"nodes have rows of {sorted(widths)} values; accepted every row {accepted}"
        )
    points = tuple((row[0], row[1]) for row in rows)
    depths = tuple(row[2] for row in rows if len(row) == 3)
    above = [i for i, z in enumerate(depths) if z < 0.0]
    if above:
        raise ConfigError(
            f"node {above[0]} has z={depths[above[0]]:g}, above the surface; accepted a seabed "
            "depth z >= 0 m, positive down"
        )
    return points, depths


def _read_rows(path: Path) -> list[list[float]]:
    """The rows of numbers of a nodes CSV file (a header row and `#` comments skipped)."""
    if not path.is_file():
        raise ConfigError(f"nodes file {path} does not exist or is not a regular file")
    if path.stat().st_size > MAX_NODES_FILE_BYTES:
        raise ConfigError(f"nodes file {path} is larger than {MAX_NODES_FILE_BYTES} bytes")
    rows: list[list[float]] = []
    header = False
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        cells = [c.strip() for c in line.split("#")[0].split(",")]
        if cells == [""]:
            continue
        try:
            values = [float(c) for c in cells]
        except ValueError:
            if not rows and not header:
                header = True  # one header row, before the data
                continue
            raise ConfigError(
                f"{path}:{number}: {line.strip()!r} is not a row of numbers; accepted "
                "'x, y' or 'x, y, z' in metres per row"
            ) from None
        if len(values) not in (2, 3) or (rows and len(values) != len(rows[0])):
            raise ConfigError(
                f"{path}:{number}: {len(values)} values; accepted 'x, y' or 'x, y, z' in "
                "metres (z: the seabed depth, positive down), the same in every row"
            )
        rows.append(values)
    return rows


def resolve(
    config: ConfigLike = None,
    n_auvs: int | None = None,
    n_nodes: int | None = None,
    layout: str | None = None,
    backend: str = "kinematic",
    nodes: NodesLike = None,
    flags: bool = False,
) -> EnvSpec:
    """The one scenario resolution: the env a caller asks for, checked.

    Args:
        config: a Config, a dict, a YAML/JSON path, or None (the paper's defaults).
        n_auvs: AUVs; None takes the config's. Contradicting a config that sets N is an error.
        n_nodes: nodes; None takes the config's (or the nodes'). Contradicting own nodes is an
            error.
        layout: "paper" or "random"; None: the config's or the file's own nodes if it sets
            them, else "paper". Asking for a layout when the nodes are given is an error.
        backend: a registered backend (`iout_mj.backends.registry.BACKENDS`).
        nodes: explicit nodes (a sequence or a CSV file), instead of the config's.
        flags: name the keywords as the command line's flags in errors (`--nodes 7`).
    """

    def named(key: str, value: Any) -> str:
        flag = {"n_auvs": "--n-auvs", "n_nodes": "--nodes", "layout": "--layout"}[key]
        return f"{flag} {value}" if flags else f"{key}={value!r}"

    if not isinstance(backend, str) or backend not in BACKENDS:
        raise ConfigError(f"backend={backend!r} is invalid: accepted one of {tuple(BACKENDS)}")
    n_auvs, n_nodes = _counts(n_auvs, n_nodes)
    if layout is not None and (not isinstance(layout, str) or layout not in LAYOUTS):
        raise ConfigError(f"layout={layout!r} is invalid: accepted one of {LAYOUTS}")
    if isinstance(config, EnvSpec):  # already resolved: keywords may only repeat it
        asked = {"n_auvs": n_auvs, "n_nodes": n_nodes, "layout": layout}
        have = {"n_auvs": config.n_auvs, "n_nodes": config.n_nodes, "layout": config.layout}
        clash = {k: v for k, v in asked.items() if v is not None and v != have[k]}
        if clash or nodes is not None:
            raise ConfigError(
                f"{clash or 'nodes='} contradicts the resolved scenario {have}: give one or "
                "the other"
            )
        return dataclasses.replace(config, backend=backend)
    base, sets = _given(config)
    own, depths = read_layout(nodes) or (None, ())
    where = (
        (f"nodes file {nodes}" if isinstance(nodes, (str, Path)) else "nodes=")
        if own is not None
        else f"config {config}"
        if isinstance(config, (str, Path))
        else "config " + " + ".join(map(str, config))
        if isinstance(config, (list, tuple)) and all(isinstance(c, (str, Path)) for c in config)
        else "the config"
    )
    if own is None and "nodes_m" in sets:
        own = base.scenario.nodes_m
    elif own is not None and "nodes_m" in sets and own != base.scenario.nodes_m:
        raise ConfigError(
            "nodes= contradicts the config's own scenario.nodes_m: give one or the other"
        )
    if n_auvs is not None and "n_auvs" in sets and n_auvs != base.scenario.n_auvs:
        raise ConfigError(
            f"{named('n_auvs', n_auvs)} contradicts {where}, which sets n_auvs="
            f"{base.scenario.n_auvs}: "
            "give one or the other"
        )
    n = base.scenario.n_auvs if n_auvs is None else n_auvs
    if own is not None:
        if n_nodes is not None and n_nodes != len(own):
            raise ConfigError(
                f"{named('n_nodes', n_nodes)} contradicts {where}, which sets {len(own)} "
                "nodes: give one or the other"
            )
        if layout is not None:
            raise ConfigError(
                f"{named('layout', layout)} contradicts {where}, which sets its own "
                f"{len(own)} nodes: leave the layout out to fly them"
            )
        scenario = dataclasses.replace(base.scenario, n_auvs=n, nodes_m=own)
        own_depths = depths or base.channel.node_depths_m
        channel = dataclasses.replace(base.channel, node_depths_m=own_depths)
        return EnvSpec(base.replace(scenario=scenario, channel=channel), "custom", backend)
    k = base.scenario.n_nodes if n_nodes is None else n_nodes
    layout = layout or "paper"
    return EnvSpec(fixed_config(n, k, base), layout, backend)
