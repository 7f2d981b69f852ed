"""Scale-out on Ray: evaluation episodes as Ray tasks, and sweeps as Ray Tune trials.

Optional (`pip install iout-mj[ray]`); this module is imported only by `--ray` and `sweep`.
A local Ray instance (loopback only) is started unless an address is given. Workers never
render (no GL context is made in them), and a trial runs the project's own trainer in-process
(no process pools inside a trial) on the CPUs Tune reserves for it.
"""

from __future__ import annotations

import csv
import itertools
import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import ray
import yaml
from ray import tune

from iout_mj.schema import ConfigError, build_dataclass, load_mapping
from iout_mj.training import TrainConfig, train

LOCAL = "local"


def connect(address: str | None) -> None:
    """Join the Ray cluster at `address`, or start a local instance on loopback (None/local)."""
    if ray.is_initialized():
        return
    local = address in (None, "", LOCAL)
    ray.init(
        address=None if local else address,
        num_cpus=os.cpu_count() if local else None,
        include_dashboard=False,
        log_to_driver=False,
        _node_ip_address="127.0.0.1" if local else None,
    )


def run_tasks(
    fn: Callable[[Any], dict[str, Any]],
    jobs: list[Any],
    address: str | None,
    on_done: Callable[[], Any],
) -> list[dict[str, Any]]:
    """`fn(job)` for every job as a Ray task of one CPU; results in completion order."""
    connect(address)
    task = ray.remote(num_cpus=1)(fn)
    pending = [task.remote(job) for job in jobs]
    results = []
    while pending:
        done, pending = ray.wait(pending, num_returns=1)
        results.extend(ray.get(done))
        on_done()
    return results


def load_sweep(path: str | Path) -> dict[str, Any]:
    """A sweep file: `base` (a training config, relative to the sweep file), `grid` (training
    config fields -> lists of values; every combination is a trial), `cpus_per_trial`,
    `metric` (of the trials' last evaluation) and `mode` (min or max)."""
    path = Path(path)
    data = load_mapping(path, "sweep file")
    known = {"base", "grid", "cpus_per_trial", "metric", "mode"}
    if unknown := sorted(set(data) - known):
        raise ConfigError(f"sweep file {path}: unknown key(s) {unknown}; accepted {sorted(known)}")
    if "base" not in data or "grid" not in data:
        raise ConfigError(f"sweep file {path}: accepted 'base' (a training config) and 'grid'")
    base_path = (path.parent / str(data["base"])).resolve()
    base = TrainConfig.load(base_path).to_dict()
    grid = data["grid"]
    if not isinstance(grid, dict) or not grid:
        raise ConfigError(f"sweep file {path}: grid must map training config fields to lists")
    for key, values in grid.items():
        if key not in base or key == "name":
            raise ConfigError(f"sweep grid key {key!r}: accepted fields of the training config")
        if not isinstance(values, list) or not values:
            raise ConfigError(f"sweep grid {key}={values!r}: accepted a non-empty list")
    trials = []
    for i, combo in enumerate(itertools.product(*grid.values())):
        overrides = dict(zip(grid, combo, strict=True))
        cfg = build_dataclass(
            TrainConfig, {**base, **overrides, "name": f"{base['name']}-{i}"}, f"trial {i}"
        )
        trials.append({"name": cfg.name, "overrides": overrides, "config": cfg.to_dict()})
    mode = data.get("mode", "min")
    if mode not in ("min", "max"):
        raise ConfigError(f"sweep mode={mode!r}: accepted 'min' or 'max'")
    cpus = data.get("cpus_per_trial", 1)
    if not isinstance(cpus, int) or cpus < 1:
        raise ConfigError(f"sweep cpus_per_trial={cpus!r}: accepted an integer >= 1")
    return {
        "trials": trials,
        "cpus_per_trial": cpus,
        "metric": str(data.get("metric", "mean_aoi_horizon")),
        "mode": mode,
    }


def _trial(param: dict[str, Any]) -> None:
    """One Tune trial: the project's trainer on its own run folder (resumed if it exists)."""
    config = param["trial"]
    cfg: TrainConfig = build_dataclass(TrainConfig, config["config"], config["name"])
    out = Path(config["out"]) / cfg.name
    resume = (out / "last").exists() or (out / "last.tmp").exists()
    state = train(cfg, out, resume=resume, progress=False, parallel=config["cpus"] > 1)
    last = state.history[-1]
    tune.report({**last, "trial": cfg.name, "num_timesteps": state.num_timesteps})


def sweep(path: str | Path, out: Path, address: str | None) -> dict[str, Any]:
    """Every trial of a sweep file as a Ray Tune trial; writes `results.csv`, `results.json`
    and `best.yaml` (the best trial's training config) into `out`."""
    spec = load_sweep(path)
    out = out.resolve()  # Tune runs trials in their own working directories
    out.mkdir(parents=True, exist_ok=True)
    connect(address)
    space = [{**t, "out": str(out), "cpus": spec["cpus_per_trial"]} for t in spec["trials"]]
    tuner = tune.Tuner(
        tune.with_resources(_trial, {"cpu": spec["cpus_per_trial"]}),
        param_space={"trial": tune.grid_search(space)},
        tune_config=tune.TuneConfig(metric=spec["metric"], mode=spec["mode"]),
        run_config=tune.RunConfig(storage_path=str(out / "tune"), name="sweep", verbose=0),
    )
    grid = tuner.fit()
    rows = []
    for i in range(len(grid)):
        result = grid[i]
        if result.error is not None:
            raise RuntimeError(f"sweep trial failed: {result.error}")
        trial = (result.config or {})["trial"]
        metrics = {k: v for k, v in (result.metrics or {}).items() if k in TRIAL_COLUMNS}
        rows.append({"trial": trial["name"], **trial["overrides"], **metrics})
    rows.sort(key=lambda r: r[spec["metric"]], reverse=spec["mode"] == "max")
    with (out / "results.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    (out / "results.json").write_text(json.dumps(rows, indent=2) + "\n")
    best = next(t for t in spec["trials"] if t["name"] == rows[0]["trial"])
    (out / "best.yaml").write_text(yaml.safe_dump(best["config"], sort_keys=False))
    return {"trials": rows, "best": best["name"], "out": str(out)}


TRIAL_COLUMNS = (
    "num_timesteps",
    "mean_aoi",
    "mean_aoi_horizon",
    "jain",
    "delivered_bits",
    "propulsion_energy_j",
    "docking_rate",
    "return",
)
