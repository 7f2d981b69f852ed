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
import socket
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import ray
import yaml
from ray import tune

from iout_mj.errors import UsageError
from iout_mj.runtime import usable_cpus
from iout_mj.schema import ConfigError, build_dataclass, load_mapping
from iout_mj.training import TrainConfig, train

LOCAL = "local"
CONNECT_TIMEOUT_S = 30.0
"""How long `connect` waits for a Ray cluster to answer before it gives up with a message."""
ADDRESSES = (
    "'local' (a new instance on this machine), 'auto' (the cluster already started on this "
    "machine), HOST:PORT (a cluster's GCS, usually port 6379) or ray://HOST:PORT (Ray Client)"
)


def _host_port(address: str) -> tuple[str, int]:
    """HOST and PORT of HOST:PORT or ray://HOST:PORT; a clear error for anything else."""
    host, _, port = address.removeprefix("ray://").rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise UsageError(f"Ray address {address!r} is invalid: accepted {ADDRESSES}")
    return host.strip("[]"), int(port)


def _reachable(address: str, timeout_s: float) -> None:
    """Fail fast, with a message, where nothing listens at the address."""
    host, port = _host_port(address)
    try:
        socket.create_connection((host, port), timeout=timeout_s).close()
    except OSError as exc:
        cause = exc.strerror or type(exc).__name__
        raise UsageError(
            f"cannot reach a Ray cluster at {address}: {cause} (waited up to {timeout_s:g} s); "
            f"start one there (ray start --head) or give another address: accepted {ADDRESSES}"
        ) from None


def _init_within(address: str, timeout_s: float) -> None:
    """`ray.init(address)` that gives up after `timeout_s` (Ray itself retries for ever when a
    port answers but no Ray cluster does)."""
    failure: list[BaseException] = []

    def init() -> None:
        try:
            ray.init(address=address, include_dashboard=False, log_to_driver=False)
        except BaseException as exc:  # handed to the caller's thread
            failure.append(exc)

    thread = threading.Thread(target=init, name="ray-connect", daemon=True)
    thread.start()
    thread.join(timeout_s)
    if thread.is_alive():
        raise UsageError(
            f"no Ray cluster answered at {address} within {timeout_s:g} s (something listens "
            f"there, but not Ray's GCS); accepted {ADDRESSES}"
        )
    if failure:
        raise UsageError(f"cannot join the Ray cluster at {address}: {failure[0]}") from failure[0]


def connect(address: str | None, timeout_s: float | None = None) -> None:
    """Join the Ray cluster at `address` within `timeout_s` (None: `CONNECT_TIMEOUT_S`), else
    a `UsageError` naming the address and what is accepted; or start a local instance on
    loopback (None or "local")."""
    if ray.is_initialized():
        return
    timeout_s = CONNECT_TIMEOUT_S if timeout_s is None else timeout_s
    if not address or address == LOCAL:
        ray.init(
            num_cpus=usable_cpus(),
            include_dashboard=False,
            log_to_driver=False,
            _node_ip_address="127.0.0.1",
            # Ray starts its workers at nice 15: beside any other busy process (a training, a
            # second test worker) they then get a few % of a core, and importing torch in
            # each took 30 s instead of 2 here. The tasks are the job: they run at our priority.
            _system_config={"worker_niceness": 0},
        )
        return
    if address != "auto":
        _reachable(address, timeout_s)
    _init_within(address, timeout_s)


def run_tasks(
    fn: Callable[[Any], dict[str, Any]],
    jobs: list[Any],
    address: str | None,
    on_done: Callable[[], Any],
    timeout_s: float | None = None,
) -> list[dict[str, Any]]:
    """`fn(job)` for every job as a Ray task of one CPU; results in completion order."""
    connect(address, timeout_s)
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


def sweep(
    path: str | Path, out: Path, address: str | None, timeout_s: float | None = None
) -> dict[str, Any]:
    """Every trial of a sweep file as a Ray Tune trial; writes `results.csv`, `results.json`
    and `best.yaml` (the best trial's training config) into `out`."""
    spec = load_sweep(path)
    out = out.resolve()  # Tune runs trials in their own working directories
    out.mkdir(parents=True, exist_ok=True)
    connect(address, timeout_s)
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
