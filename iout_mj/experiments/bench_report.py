"""Tables of a benchmark run (`iout-mj bench`, `--markdown`, `--from-json`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from iout_mj.experiments.result_files import integer, load, mapping, number, numbers, text

RATES = ("env_steps_per_s", "raw_slots_per_s", "ratio")
"""Each scenario's slot_vs_raw entries (and the same with the batch prefix)."""
TOKEN_PPO = ("kinematic", "mujoco", "trivial")
"""The general recipe's PPO steps/s entries."""
CHANNEL = "kinematic_realistic_channel_steps_per_s"
"""Steps/s under the shipped realistic channel (`bench.kinematic_rate`), N = 2, K = 13."""
CHANNEL_KEYS = ("N2_K13", "N2_K13_single_env")


def _token_ppo_lines(r: dict[str, Any]) -> list[tuple[str, str, str]]:
    """(what, value, target) of the general recipe's PPO speed, if the run measured it."""
    if "token_ppo_steps_per_s" not in r:
        return []
    t = r["token_ppo_steps_per_s"]
    return [
        (
            "token_ppo_steps_per_s, general recipe ppo-general-n2 (kinematic / mujoco)",
            f"{t['kinematic']:,.0f} / {t['mujoco']:,.0f}",
            ">= 3,000 / >= 1,000",
        ),
        (
            f"token_ppo_ratio (kinematic / trivial env {t['trivial']:,.0f} steps/s, same "
            "network and spaces)",
            f"{r['token_ppo_ratio']:.3f}",
            ">= 0.7",
        ),
    ]


def _physics_batch(r: dict[str, Any]) -> int:
    """Environments per PhysicsVecEnv call in a run (8 in runs that predate the key)."""
    return int(r.get("physics_batch", 8))


def read_result(path: Path) -> dict[str, Any]:
    """A saved benchmark run (`iout-mj bench --out`), checked by `check_result`.

    Raises:
        ResultFileError: naming the file, the entry and what is accepted.
    """
    result = load(path, "accepted a file written by `iout-mj bench --out`")
    check_result(result, str(path))
    return result


def check_result(r: Any, where: str = "the benchmark result") -> None:
    """Every entry the tables read: present, of its type, finite and >= 0."""
    r = mapping(r, where)
    machine = mapping(r.get("machine"), f"{where}: machine")
    integer(machine, "cpus", f"{where}: machine", 1)
    text(machine, "python", f"{where}: machine")
    number(r, "timestep_s", where, 0.0)
    integer(r, "substeps_per_slot", where, 1)
    integer(r, "kinematic_batch", where, 1)
    if "physics_batch" in r:
        integer(r, "physics_batch", where, 1)
    prefix = f"batch_{_physics_batch(r)}_"
    for key, row in mapping(r.get("slot_vs_raw"), f"{where}: slot_vs_raw").items():
        inner = f"{where}: slot_vs_raw.{key}"
        numbers(mapping(row, inner), [*RATES, *(prefix + k for k in RATES)], inner, 0.0)
    batch = mapping(r.get("kinematic_steps_per_s"), f"{where}: kinematic_steps_per_s")
    single = mapping(
        r.get("kinematic_single_env_steps_per_s"), f"{where}: kinematic_single_env_steps_per_s"
    )
    numbers(batch, batch, f"{where}: kinematic_steps_per_s", 0.0)
    numbers(single, batch, f"{where}: kinematic_single_env_steps_per_s", 0.0)
    numbers(
        mapping(r.get("ppo_fps"), f"{where}: ppo_fps"),
        ("physics", "kinematic", "trivial"),
        f"{where}: ppo_fps",
        0.0,
    )
    numbers(r, ("ppo_fps_ratio", "subproc_scaling", "thread_scaling", "render_fps"), where, 0.0)
    if CHANNEL in r:  # runs since the acoustic network layer's benchmark
        channel = mapping(r[CHANNEL], f"{where}: {CHANNEL}")
        numbers(channel, CHANNEL_KEYS, f"{where}: {CHANNEL}", 0.0)
    if "token_ppo_steps_per_s" in r:  # runs since the general recipe's benchmark
        numbers(
            mapping(r["token_ppo_steps_per_s"], f"{where}: token_ppo_steps_per_s"),
            TOKEN_PPO,
            f"{where}: token_ppo_steps_per_s",
            0.0,
        )
        number(r, "token_ppo_ratio", where, 0.0)
    memory = mapping(r.get("memory"), f"{where}: memory")
    numbers(memory, ("one_env_mb", "training_mb"), f"{where}: memory", 0.0)
    integer(memory, "training_envs", f"{where}: memory", 1)


def format_table(r: dict[str, Any]) -> str:
    check_result(r)
    lines = [
        f"machine: {r['machine']['cpus']} CPUs, Python {r['machine']['python']}; physics "
        f"dt {r['timestep_s']} s, {r['substeps_per_slot']} substeps per 25 s slot",
        "",
    ]
    lines.append(
        "slot_vs_raw (MuJoCo env steps/s over plain mj_step(nstep) from the same states; "
        f"target >= 0.9): one gymnasium env | PhysicsVecEnv of {_physics_batch(r)}, one thread"
    )
    b = f"batch_{_physics_batch(r)}_"
    for key, v in r["slot_vs_raw"].items():
        lines.append(
            f"  {key:<7} env {v['env_steps_per_s']:6.1f}/s raw {v['raw_slots_per_s']:6.1f}/s "
            f"ratio {v['ratio']:.3f} | env {v[b + 'env_steps_per_s']:6.1f}/s raw "
            f"{v[b + 'raw_slots_per_s']:6.1f}/s ratio {v[b + 'ratio']:.3f}"
        )
    lines.append(
        f"kinematic_steps_per_s (one core, KinematicVecEnv of {r['kinematic_batch']} envs; "
        "target >= 15000 for N2_K13) [one env through gymnasium.make; target >= 20000]"
    )
    for key, v in r["kinematic_steps_per_s"].items():
        lines.append(f"  {key:<7} {v:10.0f}   [{r['kinematic_single_env_steps_per_s'][key]:7.0f}]")
    if CHANNEL in r:
        c = r[CHANNEL]
        lines.append(
            f"  N2_K13 under the realistic channel {c['N2_K13']:10.0f}   "
            f"[{c['N2_K13_single_env']:7.0f}; target >= 20000]"
        )
    p = r["ppo_fps"]
    lines.append(
        f"ppo_fps_ratio {r['ppo_fps_ratio']:.3f} (physics {p['physics']:.0f} / trivial "
        f"{p['trivial']:.0f} steps/s; target >= 0.6); kinematic batch {p['kinematic']:.0f} steps/s"
    )
    lines += [f"{what}: {value} (target {target})" for what, value, target in _token_ppo_lines(r)]
    lines.append(f"subproc_scaling {r['subproc_scaling']:.3f} (2 workers / 1; target >= 1.8)")
    lines.append(f"thread_scaling {r['thread_scaling']:.3f} (PhysicsVecEnv, 2 rollout threads / 1)")
    lines.append(f"render_fps {r['render_fps']:.1f} (640x480, top-down + chase, overlays)")
    mem = r["memory"]
    lines.append(
        f"memory (peak RSS): one env {mem['one_env_mb']:.0f} MB; PPO on the MuJoCo backend "
        f"with {mem['training_envs']} envs (one process) {mem['training_mb']:.0f} MB"
    )
    return "\n".join(lines)


def format_markdown(r: dict[str, Any]) -> str:
    """The README's table of one run."""
    check_result(r)
    b = f"batch_{_physics_batch(r)}_"
    rows = ["| benchmark | value | target |", "| --- | --- | --- |"]
    for key, v in r["slot_vs_raw"].items():
        rows.append(
            f"| slot_vs_raw {key}, one env (env {v['env_steps_per_s']:.0f} / raw "
            f"{v['raw_slots_per_s']:.0f} slots/s) | {v['ratio']:.3f} | >= 0.9 |"
        )
        rows.append(
            f"| slot_vs_raw {key}, PhysicsVecEnv of {_physics_batch(r)} on one thread (env "
            f"{v[b + 'env_steps_per_s']:.0f} / raw {v[b + 'raw_slots_per_s']:.0f}) "
            f"| {v[b + 'ratio']:.3f} | >= 0.9 |"
        )
    single = r["kinematic_single_env_steps_per_s"]
    for key, v in r["kinematic_steps_per_s"].items():
        target = ">= 15,000 [>= 20,000]" if key == "N2_K13" else ""
        rows.append(
            f"| kinematic_steps_per_s {key}, KinematicVecEnv of {r['kinematic_batch']} "
            f"[one env, gym.make] | {v:,.0f} [{single[key]:,.0f}] | {target} |"
        )
    if CHANNEL in r:
        c = r[CHANNEL]
        rows.append(
            f"| kinematic_steps_per_s N2_K13 under the realistic channel, KinematicVecEnv of "
            f"{r['kinematic_batch']} [one env, gym.make] | {c['N2_K13']:,.0f} "
            f"[{c['N2_K13_single_env']:,.0f}] | [>= 20,000] |"
        )
    p, mem = r["ppo_fps"], r["memory"]
    rows += [
        f"| ppo_fps_ratio (physics {p['physics']:.0f} / trivial {p['trivial']:.0f} steps/s; "
        f"kinematic {p['kinematic']:.0f}) | {r['ppo_fps_ratio']:.3f} | >= 0.6 |",
        *(f"| {what} | {value} | {target} |" for what, value, target in _token_ppo_lines(r)),
        f"| subproc_scaling (2 worker processes / 1) | {r['subproc_scaling']:.3f} | >= 1.8 |",
        f"| thread_scaling (PhysicsVecEnv, 2 rollout threads / 1) | {r['thread_scaling']:.3f} | |",
        f"| render_fps 640x480 (top-down + chase, trails, links, overlay) | "
        f"{r['render_fps']:.1f} | |",
        f"| peak resident memory, one MuJoCo env (N=2, K=7) | {mem['one_env_mb']:.0f} MB "
        "| < 200 MB |",
        f"| peak resident memory, PPO on the MuJoCo backend, {mem['training_envs']} envs in one "
        f"process | {mem['training_mb']:.0f} MB | |",
    ]
    return "\n".join(rows)
