"""Validation of the paper's cubic propulsion model against MuJoCo-measured actuator power.

Every speed tested comes from the config's V_max (and dv_max): a speed above V_max would
only measure the thrust limit, not the model.

Steady state: one AUV holds each speed; measured electrical power = mean |thrust x surge
velocity| / eta_prop + H. Manoeuvres: setpoint sequences (one entry per 25 s slot), measured
energy per slot (thrust and yaw, over eta_prop, plus H) against the paper's eq. 13 with the
slot's commanded speed and measured distance. Timestep: every manoeuvre again at dt / 4.

The REMUS 100 (`physics.vehicle: remus100`) is also checked against published data, not
against itself (`published_checks`): its steady speed under Prestero's propeller thrust, its
drag against MSS's, and a +4 deg rudder step (yaw rate, surge, sway, turning circle) against
Prestero's figures; and the cubic model runs against it twice: with the C_d S fitted to its
own steady drag, and with the paper's C_d S (`validate_vehicle`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from iout_mj import vehicles
from iout_mj.agents.registry import make_policy
from iout_mj.backends.kinematic import KinematicEnvironment
from iout_mj.backends.mujoco import names, vehicle
from iout_mj.backends.mujoco.physics import AUVPhysics
from iout_mj.config import Config
from iout_mj.experiments.figures import energy_validation_figure
from iout_mj.scenarios import make_config
from iout_mj.schema import ConfigError
from iout_mj.world import propulsion

STEADY_POINTS = 8
"""Steady speeds tested: V_max / 8 to V_max in equal steps (0.5 to 4 m/s for the paper's)."""
SETTLE_S = 100.0
MEASURE_S = 25.0
TIMESTEP_CANDIDATES_S = (0.25, 0.1, 0.05, 0.025)
CONVERGENCE_TOL = 0.01


@dataclass(frozen=True)
class Maneuver:
    """Per-slot setpoints (heading in degrees, unwrapped; speed in m/s) from a start speed."""

    name: str
    start_speed_mps: float
    heading_deg: tuple[float, ...]
    speed_mps: tuple[float, ...]
    start_m: tuple[float, float] = (300.0, 500.0)
    start_heading_deg: float = 0.0


def steady_speeds_mps(cfg: Config) -> tuple[float, ...]:
    """The steady-state speeds of the config: `STEADY_POINTS` up to its V_max."""
    v_max = cfg.motion.v_max_mps
    return tuple(float(v_max * i / STEADY_POINTS) for i in range(1, STEADY_POINTS + 1))


def _mission_maneuver(cfg: Config) -> Maneuver:
    """The setpoints of one full planner mission (kinematic backend, N = 1, K = 7, seed 0)
    with the config's motion."""
    env = KinematicEnvironment(make_config(1, 7, base=cfg), seed=0)
    policy = make_policy("planner")
    env.reset()
    start = env.mission.state.positions_m[0].copy()
    start_heading = float(np.degrees(env.mission.state.heading_sp[0]))
    headings, speeds = [], []
    while True:
        ts = env.step(policy(env.mission))
        headings.append(float(np.degrees(env.mission.state.heading_sp[0])))
        speeds.append(float(env.mission.state.speed_sp[0]))
        if ts.last():
            break
    return Maneuver(
        "mission (planner, K=7)",
        cfg.motion.initial_speed_mps,
        tuple(headings),
        tuple(speeds),
        (float(start[0]), float(start[1])),
        start_heading,
    )


def commandable(man: Maneuver, cfg: Config) -> bool:
    """Whether an agent can command the manoeuvre: per slot at most dtheta_max of heading and
    dv_max of speed setpoint change (25 deg, 0.4 m/s)."""
    m = cfg.motion
    heading = np.diff([man.start_heading_deg, *man.heading_deg])
    speed = np.diff([man.start_speed_mps, *man.speed_mps])
    return bool(
        np.all(np.abs(heading) <= m.dtheta_max_deg + 1e-9)
        and np.all(np.abs(speed) <= m.dv_max_mps + 1e-9)
    )


def maneuvers(cfg: Config | None = None) -> list[Maneuver]:
    """The manoeuvres at the config's speeds (the paper's: V_max 4 m/s, dv_max 0.4 m/s): full
    speed, a dv_max ramp to it, turns at half of it, a slowdown from three quarters of it."""
    cfg = cfg or make_config(1, 7)
    v_max, dv = cfg.motion.v_max_mps, cfg.motion.dv_max_mps
    half, fast = v_max / 2, 0.75 * v_max
    zigzag = tuple(25.0 * (i % 2) for i in range(8))
    slowdown = tuple(max(fast - dv * i, 0.0) for i in range(math.ceil(fast / dv - 1e-9) + 1))
    ramp = tuple(min(round(dv * (i + 1), 6), v_max) for i in range(math.ceil(v_max / dv - 1e-9)))
    return [
        Maneuver(f"accelerate 0 to {v_max:g} m/s", 0.0, (0.0,) * 3, (v_max,) * 3),
        Maneuver(f"accelerate {dv:g} m/s per slot", 0.0, (0.0,) * len(ramp), ramp),
        Maneuver(f"90 deg turn at {half:g} m/s", half, (90.0, 90.0), (half, half)),
        Maneuver("turn 25 deg per slot to 90", half, (25.0, 50.0, 75.0, 90.0, 90.0), (half,) * 5),
        Maneuver(f"zig-zag +-25 deg at {half:g} m/s", half, zigzag, (half,) * len(zigzag)),
        Maneuver(f"slowdown {fast:g} m/s to dock", fast, (0.0,) * len(slowdown), slowdown),
        _mission_maneuver(cfg),
    ]


def _accepts_timestep(cfg: Config, dt_s: float) -> bool:
    """Whether the config's checks allow timestep `dt_s` (a short hull allows less)."""
    try:
        cfg.replace(physics=dataclasses.replace(cfg.physics, timestep_s=dt_s))
    except ConfigError:
        return False
    return True


OPEN_WATER_M = 2000.0
"""The validation flies in open water: its area reaches this far beyond the scenario's on every
side, and every pose is shifted by it. A replayed mission that drifts off its planned path (the
REMUS's does, once, to the south edge) must not meet the fence: a joint limit and the
autopilot's hold there (`vehicle.fence_hold`) are not the hull's energy."""


def _physics(cfg: Config, dt_s: float) -> AUVPhysics:
    """One AUV of the config's vehicle and motion at timestep `dt_s` (whatever the config's N:
    the meter sums every AUV's energy), in open water (`OPEN_WATER_M`)."""
    cfg = make_config(1, 7, base=cfg)
    ax, ay = cfg.scenario.area_m
    area_m = (ax + 2 * OPEN_WATER_M, ay + 2 * OPEN_WATER_M)
    cfg = cfg.replace(
        physics=dataclasses.replace(cfg.physics, timestep_s=dt_s),
        scenario=dataclasses.replace(cfg.scenario, area_m=area_m),
    )
    return AUVPhysics.from_config(cfg)


def _place(physics: AUVPhysics, xy_m: tuple[float, float], heading_rad: float, v: float) -> None:
    """One AUV at a scenario position (shifted into the open water), heading and speed."""
    shifted = np.array([xy_m], dtype=float) + OPEN_WATER_M
    physics.set_poses(shifted, np.array([heading_rad]), np.array([v]))


def steady_state(cfg: Config, speeds_mps: tuple[float, ...] | None = None) -> list[dict]:
    """Measured vs model electrical power at constant speeds (default `steady_speeds_mps`)."""
    if speeds_mps is None:
        speeds_mps = steady_speeds_mps(cfg)
    physics = _physics(cfg, cfg.physics.timestep_s)
    m = cfg.motion
    settle, measure = round(SETTLE_S / physics.dt_s), round(MEASURE_S / physics.dt_s)
    rows = []
    for v in speeds_mps:
        _place(physics, (100.0, 500.0), 0.0, v)
        physics.set_commands(np.zeros(1), np.array([v]))
        physics.step(settle)
        physics.meter.start()
        physics.step(measure)
        measured = physics.meter.read_j().sum() / MEASURE_S + m.hotel_power_w
        model = float(propulsion.propulsion_power_w(v, m))
        rows.append(
            {
                "speed_mps": float(v),
                "measured_power_w": float(measured),
                "model_power_w": model,
                "rel_error": float((measured - model) / model),
                "measured_speed_mps": float(physics.surge_mps()[0]),
            }
        )
    physics.free()
    return rows


def run_maneuver(cfg: Config, man: Maneuver, dt_s: float) -> dict[str, Any]:
    """Per-slot measured and model energy, distance and end position of one manoeuvre."""
    physics = _physics(cfg, dt_s)
    m, slot_s = cfg.motion, cfg.scenario.slot_s
    nstep = round(slot_s / physics.dt_s)
    _place(physics, man.start_m, float(np.radians(man.start_heading_deg)), man.start_speed_mps)
    measured, model, model_path, distance, ends = [], [], [], [], []
    for heading_deg, speed in zip(man.heading_deg, man.speed_mps, strict=True):
        start = physics.positions_m()[0]
        physics.meter.start()
        physics.set_commands(np.radians([heading_deg]), np.array([speed]))
        physics.step(nstep)
        end = physics.positions_m()[0]
        d = float(np.linalg.norm(end - start))
        path = np.vstack([start, physics.substep_positions_m()[:, 0]])
        flown = float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
        e = physics.meter.read_j().sum() + propulsion.hotel_energy_j(slot_s, m)
        measured.append(float(e))
        model.append(float(propulsion.slot_energy_j(speed, d, slot_s, m)))
        model_path.append(float(propulsion.slot_energy_j(speed, flown, slot_s, m)))
        distance.append(d)
        ends.append(end - OPEN_WATER_M)
    physics.free()
    return {
        "measured_j": np.array(measured),
        "model_j": np.array(model),
        "model_path_j": np.array(model_path),
        "distance_m": np.array(distance),
        "end_m": np.array(ends),
    }


def timestep_change(cfg: Config, mans: list[Maneuver], dt_s: float) -> float:
    """Largest relative change of per-slot energy, or of a slot's end position relative to the
    path travelled so far, when dt is quartered."""
    worst = 0.0
    for man in mans:
        a, b = run_maneuver(cfg, man, dt_s), run_maneuver(cfg, man, dt_s / 4)
        de = np.abs(a["measured_j"] - b["measured_j"]) / b["measured_j"]
        path_m = np.maximum(np.cumsum(b["distance_m"]), 1.0)  # travelled since the start
        dp = np.linalg.norm(a["end_m"] - b["end_m"], axis=1) / path_m
        worst = max(worst, float(de.max()), float(dp.max()))
    return worst


def validate(cfg: Config | None = None, figure: Path | None = None) -> dict[str, Any]:
    """Run the whole validation; optionally draw the figure."""
    cfg = cfg or make_config(1, 7)
    mans = maneuvers(cfg)
    steady = steady_state(cfg)
    man_rows, traces = [], []
    for man in mans:
        r = run_maneuver(cfg, man, cfg.physics.timestep_s)
        meas, mod = float(r["measured_j"].sum()), float(r["model_j"].sum())
        mod_path = float(r["model_path_j"].sum())
        man_rows.append(
            {
                "name": man.name,
                "commandable": commandable(man, cfg),
                "slots": len(man.speed_mps),
                "measured_energy_j": meas,
                "model_energy_j": mod,
                "rel_error": (meas - mod) / mod,
                "model_path_energy_j": mod_path,
                "rel_error_path": (meas - mod_path) / mod_path,
            }
        )
        traces.append((man.name, r))
    candidates = [dt for dt in TIMESTEP_CANDIDATES_S if _accepts_timestep(cfg, dt)]
    changes = {dt: timestep_change(cfg, mans, dt) for dt in candidates}
    ok = [dt for dt, c in changes.items() if c < CONVERGENCE_TOL]
    chosen = max(ok) if ok else min(candidates)
    result = {
        "steady": steady,
        "maneuvers": man_rows,
        "timestep": {
            "dt_s": chosen,
            "rel_change_quarter_dt": changes[chosen],
            "candidates": {str(k): v for k, v in changes.items()},
            "configured_dt_s": cfg.physics.timestep_s,
        },
    }
    if figure is not None:
        energy_validation_figure(result, traces, figure)
    return result


def format_table(result: dict[str, Any]) -> str:
    lines = [
        "Steady state (electrical power, W)",
        f"{'speed m/s':>10} {'measured':>10} {'model':>10} {'rel.err':>9}",
    ]
    for r in result["steady"]:
        lines.append(
            f"{r['speed_mps']:>10.1f} {r['measured_power_w']:>10.2f} "
            f"{r['model_power_w']:>10.2f} {r['rel_error']:>+9.2%}"
        )
    lines += [
        "",
        "Manoeuvres (energy over the manoeuvre, kJ; model with the chord of each slot and with "
        "the path flown; * = an agent can command it)",
        f"{'manoeuvre':<30} {'slots':>5} {'measured':>9} {'chord':>9} {'gap':>8} "
        f"{'path':>9} {'gap':>8}",
    ]
    for r in result["maneuvers"]:
        name = ("* " if r["commandable"] else "  ") + r["name"]
        lines.append(
            f"{name:<30} {r['slots']:>5} {r['measured_energy_j'] / 1e3:>9.2f} "
            f"{r['model_energy_j'] / 1e3:>9.2f} {r['rel_error']:>+8.1%} "
            f"{r['model_path_energy_j'] / 1e3:>9.2f} {r['rel_error_path']:>+8.1%}"
        )
    ts = result["timestep"]
    cands = ", ".join(f"dt={k} s: {v:.2%}" for k, v in ts["candidates"].items())
    lines += [
        "",
        f"Timestep: largest dt with < 1% change when quartered: {ts['dt_s']} s "
        f"({ts['rel_change_quarter_dt']:.3%}); {cands}",
    ]
    return "\n".join(lines)


# Published REMUS 100 figures (Prestero 2001, "P"; Fossen's MSS remus100.m, "MSS").
PRESTERO_THRUST_N = 3.86
"""Propeller thrust at 1500 rpm, P Table C.9."""
PRESTERO_SPEED_MPS = 1.54
"""Steady speed at 1500 rpm, P Table 8.1 (and Section 8.1.1)."""
RUDDER_STEP_DEG = 4.0
"""P Figs. 8-1 to 8-3: rudder +4 deg at 1500 rpm from the 1.54 m/s trim."""
PRESTERO_TURN = {"yaw_rate_dps": 9.0, "surge_mps": 1.39, "sway_mps": 0.07}
"""P Figs. 8-1 to 8-3 as a published summary of the thesis reads them off the figures: mean yaw
rate 25-38 s 9.0 deg/s, surge in the turn 1.38-1.40 m/s, sway about 0.07 m/s (signs dropped:
P's axes are starboard and down). Not yet checked against the thesis's own figures (its text was
not among the sources searched); the MuJoCo hull built from P's Appendix B coefficients alone
lands within 6 % of them (yaw rate) and 1.3 % (turning diameter), as P's simulation would."""
MSS_DRAG_KGPM = 0.5 * 1026.0 * 0.42 * math.pi * (0.19 / 2) ** 2
"""MSS remus100.m: Cd = 0.42 (Allen et al. 2000) on the frontal area pi (D/2)^2, D = 0.19 m,
rho = 1026 kg/m^3: 6.13 kg/m."""
Y_UUDR_KGPM = 9.64
"""Rudder lift, P Appendix B (Y_uudr, per radian)."""
TURN_SETTLE_S, TURN_MEASURE_S = 60.0, 60.0


def turning_diameter_m(speed_mps: float, yaw_rate_dps: float) -> float:
    """Diameter of the steady turn: 2 U / r."""
    return 2.0 * speed_mps / math.radians(abs(yaw_rate_dps))


def _constant_thrust(physics: AUVPhysics, thrust_n: float) -> None:
    """Turn the speed servo into a constant force and the heading servo off (open loop)."""
    m = physics.model.ptr
    for name, bias0 in ((names.THRUST, thrust_n), (names.YAW_ACTUATOR, 0.0)):
        i = m.actuator(names.auv_prefix(0) + name).id
        m.actuator_gainprm[i, :] = 0.0
        m.actuator_biasprm[i, :] = 0.0
        m.actuator_biasprm[i, 0] = bias0
        m.actuator_forcerange[i] = [-abs(bias0), abs(bias0)]


def _body_velocity(physics: AUVPhysics) -> tuple[float, float, float]:
    """Surge, sway (to port) and yaw rate of AUV 0."""
    yaw = float(physics.yaw_rad()[0])
    vx, vy = physics.velocities_mps()[0]
    r = float(physics.data.ptr.qvel[physics._vyaw[0]])
    return (
        float(np.cos(yaw) * vx + np.sin(yaw) * vy),
        float(-np.sin(yaw) * vx + np.cos(yaw) * vy),
        r,
    )


def rudder_step(cfg: Config, rudder_deg: float = RUDDER_STEP_DEG) -> dict[str, float]:
    """P's rudder step in MuJoCo: from P's steady speed under P's thrust, a rudder side force
    Y_uudr u^2 delta at the fins (updated every substep from the measured surge); the turn's
    means over TURN_MEASURE_S after TURN_SETTLE_S."""
    physics = _physics(cfg, cfg.physics.timestep_s)
    _constant_thrust(physics, PRESTERO_THRUST_N)
    physics.set_poses(np.array([[500.0, 500.0]]), np.zeros(1), np.array([PRESTERO_SPEED_MPS]))
    rudder = physics.model.ptr.actuator(names.auv_prefix(0) + vehicle.RUDDER).id
    delta = math.radians(rudder_deg)
    settle = round(TURN_SETTLE_S / physics.dt_s)
    samples = []
    for k in range(settle + round(TURN_MEASURE_S / physics.dt_s)):
        u, v, r = _body_velocity(physics)
        physics.data.ptr.ctrl[rudder] = -Y_UUDR_KGPM * u * u * delta  # to starboard: P's +
        physics.step(1)
        if k >= settle:
            samples.append(_body_velocity(physics))
    physics.free()
    u, v, r = np.mean(samples, axis=0)
    speed = float(math.hypot(u, v))
    return {
        "surge_mps": float(u),
        "sway_mps": float(abs(v)),
        "yaw_rate_dps": float(abs(math.degrees(r))),
        "turning_diameter_m": turning_diameter_m(speed, math.degrees(r)),
    }


def steady_speed_under_thrust(cfg: Config, thrust_n: float) -> float:
    """Steady surge speed of AUV 0 under a constant propeller force."""
    physics = _physics(cfg, cfg.physics.timestep_s)
    _constant_thrust(physics, thrust_n)
    physics.set_poses(np.array([[100.0, 500.0]]), np.zeros(1), np.zeros(1))
    physics.step(round(2 * SETTLE_S / physics.dt_s))
    speed = float(physics.surge_mps()[0])
    physics.free()
    return speed


def published_checks(cfg: Config) -> list[dict[str, Any]]:
    """The vehicle in MuJoCo against published figures: rows of quantity, MuJoCo, published
    value and its source."""
    speed = steady_speed_under_thrust(cfg, PRESTERO_THRUST_N)
    drag = vehicle.hull_drag_nspm2(cfg)
    turn = rudder_step(cfg)
    p_turn = PRESTERO_TURN
    p_diameter = turning_diameter_m(
        math.hypot(p_turn["surge_mps"], p_turn["sway_mps"]), p_turn["yaw_rate_dps"]
    )
    v = PRESTERO_SPEED_MPS
    rows = [
        ("steady speed at 3.86 N thrust, m/s", speed, v, "Prestero Tables C.9, 8.1"),
        ("drag at 1.54 m/s, N", drag * v**2, MSS_DRAG_KGPM * v**2, "MSS remus100.m (Cd 0.42)"),
        (
            "rudder +4 deg: yaw rate, deg/s",
            turn["yaw_rate_dps"],
            p_turn["yaw_rate_dps"],
            "P Fig. 8-3",
        ),
        ("rudder +4 deg: surge, m/s", turn["surge_mps"], p_turn["surge_mps"], "P Fig. 8-2"),
        ("rudder +4 deg: sway, m/s", turn["sway_mps"], p_turn["sway_mps"], "P Fig. 8-2"),
        (
            "rudder +4 deg: turning diameter, m",
            turn["turning_diameter_m"],
            p_diameter,
            "2 U / r of P Figs. 8-2, 8-3",
        ),
    ]
    return [
        {
            "quantity": q,
            "mujoco": float(m),
            "published": float(p),
            "rel_error": float((m - p) / p),
            "source": src,
        }
        for q, m, p, src in rows
    ]


def paper_cd_s(cfg: Config) -> Config:
    """`cfg` with the paper's C_d and S in the cubic model (the hull keeps its own drag)."""
    paper = Config().motion
    return cfg.replace(
        motion=dataclasses.replace(
            cfg.motion,
            drag_coefficient=paper.drag_coefficient,
            wetted_area_m2=paper.wetted_area_m2,
        )
    )


def validate_vehicle(cfg: Config, figure: Path | None = None) -> dict[str, Any]:
    """`validate` for the config's vehicle; for a vehicle with drag of its own (the REMUS) also
    the published checks and the cubic model with the paper's C_d S."""
    result = validate(cfg, figure=figure)
    if vehicles.get(cfg.physics.vehicle).hull_drag_nspm2 is not None:
        result["vehicle"] = cfg.physics.vehicle
        result["published"] = published_checks(cfg)
        paper = validate(paper_cd_s(cfg))
        result["paper_cd_s"] = {k: paper[k] for k in ("steady", "maneuvers")}
    return result


def format_vehicle_table(result: dict[str, Any]) -> str:
    """`format_table`, then the published checks and the paper's C_d S where there are any."""
    if "published" not in result:  # the calibrated torpedo: the table alone, as before
        return format_table(result)
    lines = [
        f"Vehicle: {result['vehicle']}, cubic model with C_d S fitted to its steady drag",
        "",
        format_table(result),
        "",
        "Against published data (Prestero 2001 = P; Fossen's MSS remus100.m)",
        f"{'quantity':<36} {'MuJoCo':>8} {'published':>9} {'rel.err':>8}  source",
    ]
    for r in result["published"]:
        lines.append(
            f"{r['quantity']:<36} {r['mujoco']:>8.3f} {r['published']:>9.3f} "
            f"{r['rel_error']:>+8.1%}  {r['source']}"
        )
    paper = format_table({**result["paper_cd_s"], "timestep": result["timestep"]})
    lines += [
        "",
        "The same hull against the cubic model with the paper's C_d S (0.006 x 3 m^2)",
        paper.split("\n\nTimestep")[0],
    ]
    return "\n".join(lines)
