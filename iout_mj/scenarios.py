"""Scenarios: node layouts and the one place where (config, N, K, layout) become a `Config`.

Every entry point (gymnasium, the VecEnvs, the CLI, evaluation, training, benchmarks) resolves
its scenario here. Layouts:

- "paper": the paper's 7- or 13-node layout (the authors' code);
- "random": a new seeded layout every episode, drawn from the task RNG;
- `fixed_config(N, K)`: the paper's layout for K = 7 and 13, else one seeded layout per K
  (`random_layout(K, seed=K)`), the same for every policy and episode (evaluation, CLI).

`SCENARIOS` names the scenarios the test suite runs every invariant over (`paper-k7`,
`paper-k13`, `random-k{K}`), as dm_control's `suite.ALL_TASKS`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from iout_mj.config import MAX_NODES, MIN_NODES, PAPER_LAYOUTS, Config, Point, ScenarioConfig
from iout_mj.schema import ConfigError, require

LAYOUTS = ("paper", "random")
ConfigLike = Config | dict[str, Any] | str | Path | None
"""What `config=` accepts everywhere: a Config, a dict, a YAML/JSON path, or None."""


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
    seed: int,
    scenario: ScenarioConfig | None = None,
    min_spacing_m: float = 80.0,
    margin_m: float = 50.0,
) -> tuple[Point, ...]:
    """Seeded node layout inside the area, `min_spacing_m` apart and outside the dock zone."""
    require(
        MIN_NODES <= n_nodes <= MAX_NODES,
        "n_nodes",
        n_nodes,
        f"an integer from {MIN_NODES} to {MAX_NODES}",
    )
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


def load_config(config: ConfigLike) -> Config:
    """A Config from a Config, a dict, a YAML/JSON path, or None (the paper's defaults)."""
    if config is None:
        return Config()
    if isinstance(config, Config):
        return config
    if isinstance(config, dict):
        return Config.from_dict(config)
    if isinstance(config, (str, Path)):
        return Config.load(config)
    raise ConfigError(f"config={config!r}: accepted a Config, a dict, a file path or None")


def resolve_config(
    config: ConfigLike,
    n_auvs: int | None = None,
    n_nodes: int | None = None,
    layout: str = "paper",
    layout_seed: int = 0,
) -> Config:
    """The env's Config: `config` with N, K and the layout applied (None keeps the config's)."""
    base = load_config(config)
    if layout not in LAYOUTS:
        raise ConfigError(f"layout={layout!r} is invalid: accepted one of {LAYOUTS}")
    if n_auvs is None and n_nodes is None and layout == "paper":
        return base
    n = base.scenario.n_auvs if n_auvs is None else n_auvs
    k = base.scenario.n_nodes if n_nodes is None else n_nodes
    return make_config(n, k, layout, seed=layout_seed, base=base)


def fixed_config(n_auvs: int, n_nodes: int, base: ConfigLike = None) -> Config:
    """The paper's layout for K = 7 and 13, else the seeded layout `random_layout(K, seed=K)`:
    one fixed layout per K (evaluation, missions, benchmarks)."""
    layout = "paper" if n_nodes in PAPER_LAYOUTS else "random"
    return make_config(n_auvs, n_nodes, layout, seed=n_nodes, base=load_config(base))
