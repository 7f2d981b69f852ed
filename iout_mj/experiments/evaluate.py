"""Seeded evaluation of policies over (N, K) grids, in parallel worker processes.

Episode e of every (policy, N, K) uses seed S + e, so every policy starts from the same states.
Every cell is resolved like any env (`scenarios.resolve`): "paper" is the paper's layout for
K = 7 and 13 and one seeded layout per K otherwise, "random" a new layout every episode (the
same for every policy), and a config's own nodes (or a nodes file) are flown in every episode.

A learned policy P is flown as each of its training seeds: seed 0 is P itself, seed k >= 1 the
policy `P-seed<k>` resolved like P (a shipped name, `ppo-general` per N, or a folder); its rows
keep the label P and carry `training_seed`. A baseline has no training seed (null), flown once.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import multiprocessing as mp
import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from itertools import product
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from iout_mj.agents.policies import (
    LEGACY_FILES,
    PER_N_FAMILIES,
    for_n,
    load_policy,
    split_search,
)
from iout_mj.agents.policy_format import MANIFEST
from iout_mj.agents.registry import POLICIES
from iout_mj.agents.rollout import run_episode
from iout_mj.agents.shield import DOCK_SUFFIX, split_shield
from iout_mj.envs import ENV_ID
from iout_mj.errors import (
    MAX_SEED,
    PolicyError,
    PolicyMismatchError,
    UsageError,
    require_integer,
    require_seed,
)
from iout_mj.files import write_atomic
from iout_mj.mission.stats import SUMMARY_KEYS, episode_summary
from iout_mj.runtime import cpu_bounded, usable_cpus
from iout_mj.scenarios import ConfigLike, EnvSpec, NodesLike, given_keys, resolve

TRACE_NODES = 7
MAX_EPISODES = 100_000
"""Episodes of one evaluation at most (cells x episodes; hours of CPU, and their rows in
memory)."""


@dataclass(frozen=True)
class Job:
    """One episode of an evaluation (picklable: it crosses into a worker process)."""

    policy: str
    spec: EnvSpec
    seed: int
    keep_trace: bool = False
    trust_pickle: bool = False
    label: str | None = None
    """The policy's name in the rows (default `policy`): a training seed's variant keeps P's."""
    training_seed: int | None = None


def scenario_grid(
    base: ConfigLike,
    n_auvs: list[int] | None,
    nodes: list[int] | None,
    layout: str | None,
    backend: str,
    nodes_file: NodesLike = None,
) -> list[EnvSpec]:
    """The scenarios of an evaluation, one per (N, K). A list left out is the config's own
    value if it sets one (its nodes: in every episode), else N = 1, 2 and K = 7."""
    sets = given_keys(base) | ({"nodes_m"} if nodes_file is not None else set())
    ns: list[int | None] = list(n_auvs) if n_auvs else ([None] if "n_auvs" in sets else [1, 2])
    ks: list[int | None] = list(nodes) if nodes else ([None] if "nodes_m" in sets else [7])
    return [resolve(base, n, k, layout, backend, nodes_file, flags=True) for n in ns for k in ks]


def scenario_env(spec: EnvSpec) -> Any:
    """The env of one evaluation cell."""
    return gym.make(ENV_ID, backend=spec.backend, config=spec)


def _episode(job: Job) -> dict[str, Any]:
    env = scenario_env(job.spec)
    policy = load_policy(job.policy, env, job.seed, job.trust_pickle)
    metrics = run_episode(env, policy, job.seed)
    row: dict[str, Any] = {
        "policy": job.label or job.policy,
        "n_auvs": job.spec.n_auvs,
        "n_nodes": job.spec.n_nodes,
        "layout": job.spec.layout,
        "seed": job.seed,
        "training_seed": job.training_seed,
        "backend": job.spec.backend,
        "noise_model": job.spec.config.acoustics.noise_model,
        "max_current_mps": job.spec.config.physics.max_current_mps,
        "channel": job.spec.config.channel.label,
        **metrics,
    }
    if job.keep_trace:
        row["trace"] = env.unwrapped.mission.trace()
    env.close()
    return row


def _one_torch_thread() -> None:
    """A worker's policies run on one torch thread: the workers already share the cores, and
    a small network on a few rows ran 12x slower on two threads than on one with the cores
    busy (rollout search, N = 2, K = 11)."""
    import torch

    torch.set_num_threads(1)


@contextmanager
def _one_torch_thread_here() -> Iterator[None]:
    """Jobs run in this process as in a worker, on one torch thread (restored after): with
    `workers=1` beside two or three trainings a rollout search on MuJoCo ran 4 to 20x slower on
    torch's default threads, and a worker count should not change what the policies compute."""
    import torch

    before = torch.get_num_threads()
    _one_torch_thread()
    try:
        yield
    finally:
        torch.set_num_threads(before)


def _pool(workers: int) -> Any:
    """Worker processes that leave Ctrl-C to this one, which ends them (one message, not a
    traceback from every worker): they start with SIGINT ignored, and keep it so."""
    if threading.current_thread() is not threading.main_thread():  # signals: the main one's
        return mp.get_context("spawn").Pool(workers, initializer=_one_torch_thread)
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        return mp.get_context("spawn").Pool(workers, initializer=_one_torch_thread)
    finally:
        signal.signal(signal.SIGINT, previous)


def _cells(
    policies: list[str], specs: list[EnvSpec], trust_pickle: bool, training_seeds: list[int]
) -> tuple[list[tuple[str, EnvSpec]], list[str]]:
    """The (policy, scenario) cells a policy can serve (decided by its first training seed),
    and why the others are skipped: a policy made for other spaces, or one that exists for
    some cells and not for this one (`ppo-general` at an N nothing is shipped for). A policy
    that serves no cell for want of existing (a wrong name, an unreadable file), or a learned
    policy's training seed that is missing or cannot serve a cell its first seed serves,
    fails here, before any worker starts."""
    cells, skipped = [], []
    missing: dict[str, list[tuple[EnvSpec, PolicyError]]] = {}  # policy -> cells it lacks
    for name, spec in product(policies, specs):
        seeds = training_seeds if learned(name) else [0]
        env = scenario_env(dataclasses.replace(spec, backend="kinematic"))
        try:
            _load_seed(name, seeds[0], spec, env, trust_pickle)
        except PolicyMismatchError as exc:
            skipped.append(f"skipped {name} at N={spec.n_auvs}, K={spec.n_nodes}: {exc}")
        except PolicyError as exc:
            missing.setdefault(name, []).append((spec, exc))
        else:
            _load_other_seeds(name, seeds, spec, env, trust_pickle)
            cells.append((name, spec))
        finally:
            env.close()
    for name, lacking in missing.items():
        if all(served != name for served, _ in cells):
            raise lacking[0][1]  # it exists for no asked cell: a wrong name, a bad file
        skipped.extend(
            f"skipped {name} at N={spec.n_auvs}, K={spec.n_nodes}: {error}"
            for spec, error in lacking
        )
    return cells, skipped


def _load_other_seeds(
    name: str, seeds: list[int], spec: EnvSpec, env: Any, trust_pickle: bool
) -> None:
    """Every training seed after the first must exist and serve the cell the first serves."""
    for k in seeds[1:]:
        try:
            _load_seed(name, k, spec, env, trust_pickle)
        except PolicyMismatchError as exc:
            raise PolicyError(
                f"training seed {k} of {name!r} cannot serve N={spec.n_auvs}, "
                f"K={spec.n_nodes}, which seed {seeds[0]} serves: {exc}. Accepted: "
                "training seeds of one policy made for the same spaces"
            ) from exc


def _jobs(
    cells: list[tuple[str, EnvSpec]],
    training_seeds: list[int],
    episodes: int,
    seed: int,
    trust_pickle: bool,
) -> list[Job]:
    """Every episode of every cell: a learned policy's once per training seed (the first keeps
    the trace), a baseline's once."""
    jobs = []
    for name, spec in cells:
        seeds: list[int | None] = list(training_seeds) if learned(name) else [None]
        for k, e in product(seeds, range(episodes)):
            variant = name if k is None else seed_variant(name, k, spec.n_auvs)
            trace = e == 0 and k == seeds[0] and _traced(spec)
            jobs.append(Job(variant, spec, seed + e, trace, trust_pickle, name, k))
    return jobs


def learned(name: str) -> bool:
    """Whether a policy name is a trained policy (it has training seeds), not a baseline
    (shielded or not)."""
    return split_shield(name)[0] not in POLICIES


def seed_variant(name: str, training_seed: int, n_auvs: int) -> str:
    """The policy that is training seed `training_seed` of the learned policy `name` in an env
    of `n_auvs` AUVs: `name` itself for seed 0, else `name-seed<k>` resolved like `name`
    (`ppo-general` -> `ppo-general-n<N>-seed<k>`, `runs/gen` -> `runs/gen-seed<k>`, a policy
    file `runs/gen/policy.json` -> `runs/gen-seed<k>/policy.json`; a path through a run folder
    named for seed 0, as `train --seed 0` names it, has that folder's seed replaced:
    `runs/gen-seed0/best` -> `runs/gen-seed<k>/best`)."""
    if training_seed == 0:
        return name
    unshielded, shielded = split_shield(name)
    if shielded:  # P+dock: training seed k of P, shielded
        return seed_variant(unshielded, training_seed, n_auvs) + DOCK_SUFFIX
    base, candidates = split_search(name)
    if candidates is not None:  # P+rollout: training seed k of P, searched the same way
        return seed_variant(base, training_seed, n_auvs) + name[len(base) :]
    suffix = f"-seed{training_seed}"
    if name in PER_N_FAMILIES:
        return for_n(name, n_auvs) + suffix
    path = Path(name)
    seed0 = [i for i, part in enumerate(path.parts) if part.endswith("-seed0")]
    if seed0:
        i = seed0[-1]
        parts = path.parts
        return str(Path(*parts[:i], parts[i].removesuffix("-seed0") + suffix, *parts[i + 1 :]))
    if path.name in (MANIFEST, *LEGACY_FILES) and path.is_file():
        return str(path.parent.with_name(path.parent.name + suffix) / path.name)
    return str(path) + suffix


def _load_seed(name: str, k: int, spec: EnvSpec, env: Any, trust_pickle: bool) -> None:
    """Load training seed `k` of `name` for `spec`'s env: a mismatch raises
    `PolicyMismatchError` as it is; a missing or unreadable seed variant a `PolicyError` naming
    the policy it looked for and what is accepted."""
    variant = seed_variant(name, k, spec.n_auvs)
    try:
        load_policy(variant, env, trust_pickle=trust_pickle)
    except PolicyMismatchError:
        raise
    except PolicyError as exc:
        if variant == name:
            raise
        pattern = variant.replace(f"-seed{k}", "-seed<k>")
        raise PolicyError(
            f"training seed {k} of {name!r} at N={spec.n_auvs}, K={spec.n_nodes} is the policy "
            f"{variant!r} (training seed 0 is {name!r} itself, k >= 1 is {pattern!r}); it "
            f"cannot be used: {exc}"
        ) from exc


def _once_each(what: str, values: list[Any]) -> None:
    """Refuse a list that names a value twice (its cell would count the same episodes twice)."""
    twice = sorted({str(v) for v in values if values.count(v) > 1})
    if twice:
        raise UsageError(f"{what} {', '.join(twice)} given more than once: accepted each once")


def summarize(episodes: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Mean and standard deviation per (policy, N, K, layout, backend), over every episode of
    the cell (its training seeds pooled), and how many training seeds it holds (0: a baseline)."""
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for e in episodes:
        cell = (e["policy"], e["n_auvs"], e["n_nodes"], e["layout"], e["backend"])
        groups.setdefault(cell, []).append(e)
    rows = []
    for (policy, n, k, layout, backend), eps in sorted(groups.items()):
        summaries = [episode_summary(e) for e in eps]
        row: dict[str, Any] = {
            "policy": policy,
            "n_auvs": n,
            "n_nodes": k,
            "layout": layout,
            "backend": backend,
            "noise_model": eps[0]["noise_model"],
            "max_current_mps": eps[0]["max_current_mps"],
            "channel": eps[0]["channel"],
            "episodes": len(eps),
            "training_seeds": len({e.get("training_seed") for e in eps} - {None}),
        }
        for key in SUMMARY_KEYS:
            values = [e[key] for e in summaries]
            row[key] = float(np.mean(values))
            row[key + "_std"] = float(np.std(values))
        rows.append(row)
    return rows


def _run(
    jobs: list[Job],
    workers: int,
    ray_address: str | None,
    ray_timeout_s: float | None,
    on_done: Callable[[], Any],
) -> list[dict[str, Any]]:
    """Every job's episode row: on Ray, in `workers` processes, or here."""
    if ray_address is not None:
        from iout_mj.experiments import ray_jobs  # ray is optional: imported only when asked

        return ray_jobs.run_tasks(_episode, jobs, ray_address, on_done, ray_timeout_s)
    results = []
    if workers > 1:
        with _pool(workers) as pool:
            for row in pool.imap_unordered(_episode, jobs):
                results.append(row)
                on_done()
    else:
        with _one_torch_thread_here():
            for job in jobs:
                results.append(_episode(job))
                on_done()
    return results


def evaluate(
    policies: list[str],
    n_auvs: list[int] | None,
    nodes: list[int] | None,
    episodes: int,
    seed: int,
    backend: str,
    workers: int | None = None,
    progress: bool = True,
    trust_pickle: bool = False,
    skipped: list[str] | None = None,
    layout: str | None = None,
    base: ConfigLike = None,
    ray_address: str | None = None,
    ray_timeout_s: float | None = None,
    nodes_file: NodesLike = None,
    training_seeds: list[int] | None = None,
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """Run every (policy, N, K, episode) a policy can serve; returns (summary rows, episode
    rows). The scenarios are `scenario_grid`'s (the env config `base`: current, noise,
    reward, physics, and its own N or nodes if it sets them). Cells a trained policy cannot serve
    (another N, K or action mapping) are skipped and said in `skipped`. With `ray_address`
    ("local" or a cluster address, joined within `ray_timeout_s`) the episodes run as Ray
    tasks: the same rows. `workers` is at most the CPUs this process may use (default: as
    many as there are CPUs and episodes); a policy, N or K given twice is refused. A learned
    policy flies each of `training_seeds` (default [0]: itself; `seed_variant`)."""
    training_seeds = _check_arguments(policies, n_auvs, nodes, episodes, seed, training_seeds)
    named = (("policy", policies), ("N", n_auvs), ("K", nodes), ("training seed", training_seeds))
    for what, values in named:
        _once_each(what, list(values or []))
    if workers is not None:
        cpu_bounded(workers, "workers", 1)
    specs = scenario_grid(base, n_auvs, nodes, layout, backend, nodes_file)
    cells, notes = _cells(policies, specs, trust_pickle, training_seeds)
    if skipped is not None:
        skipped.extend(notes)
    if not cells:
        raise PolicyError("no policy can serve any of the asked (N, K): " + "; ".join(notes))
    jobs = _jobs(cells, training_seeds, episodes, seed, trust_pickle)
    if len(jobs) > MAX_EPISODES:
        raise UsageError(
            f"{len(cells)} cells x {episodes} episodes (x training seeds of learned policies) = "
            f"{len(jobs)} episodes: accepted at most {MAX_EPISODES} in one evaluation"
        )
    workers = workers or min(len(jobs), usable_cpus())
    quiet: dict[str, Any] = {} if progress else {"disable": True}  # else tqdm's (TQDM_DISABLE)
    with tqdm(total=len(jobs), desc="episodes", unit="ep", **quiet) as bar:
        results = _run(jobs, workers, ray_address, ray_timeout_s, lambda: bar.update(1))
    results.sort(key=_row_order)
    return summarize(results), results


def _check_arguments(
    policies: Any, n_auvs: Any, nodes: Any, episodes: Any, seed: Any, training_seeds: Any
) -> list[int]:
    """`evaluate`'s arguments, checked before any policy is read; returns the training seeds
    (default [0]). Every episode seed S + e must be a seed the backends take."""
    if isinstance(policies, str) or not isinstance(policies, (list, tuple)) or not policies:
        raise UsageError(
            f"policies={policies!r:.80}: accepted a non-empty list of policy names or folders"
        )
    if not all(isinstance(p, str) for p in policies):
        raise UsageError(f"policies={policies!r:.80}: accepted names or folders as strings")
    for what, values in (("n_auvs", n_auvs), ("nodes", nodes)):
        if values is not None and not isinstance(values, (list, tuple)):
            raise UsageError(f"{what}={values!r:.80}: accepted a list of integers, or None")
    require_integer(episodes, "episodes", 1, MAX_EPISODES)
    require_seed(seed)
    if seed + episodes - 1 > MAX_SEED:
        raise UsageError(
            f"seed={seed} with episodes={episodes}: the episode seeds run to "
            f"{seed + episodes - 1}; accepted seed + episodes - 1 <= {MAX_SEED}"
        )
    seeds = [0] if training_seeds is None else list(training_seeds)
    if not seeds:
        raise UsageError("training_seeds=[]: accepted one or more integers >= 0 (or None: [0])")
    for i, k in enumerate(seeds):
        require_integer(k, f"training_seeds[{i}]", 0, MAX_SEED)
    return seeds


def _row_order(row: dict[str, Any]) -> tuple[Any, ...]:
    """Episode rows by policy, N, K, training seed (a baseline's first), episode seed."""
    trained = row["training_seed"]
    return (
        row["policy"],
        row["n_auvs"],
        row["n_nodes"],
        -1 if trained is None else trained,
        row["seed"],
    )


def _traced(spec: EnvSpec) -> bool:
    """Whether the first episode of a cell keeps its trace (the figures' K = 7, or own nodes)."""
    return spec.n_nodes == TRACE_NODES or spec.layout == "custom"


def save(rows: list[dict[str, Any]], episodes: list[dict[str, Any]], out: Path) -> None:
    """results.json, results.csv, episodes.json and traces.json (one K = 7 episode each), each
    replaced whole; a failed write (a full disk, ...) raises `UsageError` naming the file."""
    if not rows:
        raise UsageError("no summary rows to save: accepted the rows `evaluate` returns")
    table = io.StringIO(newline="")
    writer = csv.DictWriter(table, fieldnames=list(rows[0]))
    writer.writeheader()
    writer.writerows(rows)
    traces = {f"{e['policy']}, N={e['n_auvs']}": e.pop("trace") for e in episodes if "trace" in e}
    try:  # strict JSON: a NaN or infinity would be written as a bare token no reader accepts
        files = {
            "results.json": json.dumps(rows, indent=2, allow_nan=False) + "\n",
            "results.csv": table.getvalue(),
            "episodes.json": json.dumps(episodes, allow_nan=False) + "\n",
            "traces.json": json.dumps(traces, allow_nan=False) + "\n",
        }
    except ValueError as exc:
        raise UsageError(
            f"cannot save results holding a non-finite number ({exc}): accepted finite metrics"
        ) from exc
    path = out
    try:
        out.mkdir(parents=True, exist_ok=True)
        for name, text in files.items():
            path = out / name
            write_atomic(path, text.encode())
    except OSError as exc:
        raise UsageError(f"cannot write {path}: {exc.strerror or exc}") from exc


def format_table(rows: list[dict[str, Any]]) -> str:
    """Mean ± std per row; AoI(T) is over the mission, AoI(Tmax) over the whole horizon."""
    cols = [
        ("mean_aoi", "AoI(T)", 1.0, 2),
        ("mean_aoi_horizon", "AoI(Tmax)", 1.0, 2),
        ("objective", "objective", 1.0, 2),
        ("jain", "Jain", 1.0, 2),
        ("delivered_bits", "data Mbit", 1e-6, 1),
        ("propulsion_energy_j", "kJ/AUV", 1e-3, 0),
    ]
    width = max([14, *(len(str(r["policy"])) + 1 for r in rows)])  # a path as a policy fits
    head = f"{'policy':<{width}}{'N':>2}{'K':>4}" + "".join(f"{c[1]:>15}" for c in cols)
    lines = [head + f"{'docked':>8}{'coll.':>7}"]
    for r in rows:
        cells = "".join(
            f"{r[key] * scale:>8.{nd}f} ± {r[key + '_std'] * scale:<4.{nd}f}"
            for key, _, scale, nd in cols
        )
        lines.append(
            f"{r['policy']:<{width}}{r['n_auvs']:>2}{r['n_nodes']:>4}{cells}"
            f"{r['docking_rate']:>8.0%}{r['collisions']:>7.2f}"
        )
    return "\n".join(lines)
