"""Builds the MuJoCo scene: N AUVs of the config's vehicle, nodes, dock and arena, from a Config.

`physics.vehicle` picks the MJCF (`iout_mj.vehicles`): 'paper-torpedo' (assets/auv.xml,
below) or 'remus100' (assets/remus100.xml, every number cited there and in vehicles.py).
Either way the hull's straight-ahead surge drag is set here from `hull_drag_nspm2` (the
torpedo's: the config's rho C_d S / 2; the REMUS's: its own X_uu), the speed servo's
feedforward uses that drag, and its thrust limit is that drag at V_max.

The paper's torpedo (assets/auv.xml), with its sources:

- Hull: 3.0 m x 0.32 m torpedo, rigid mass 240 kg (neutrally buoyant: its displaced volume,
  pi 0.16^2 3.0 m^3 = 0.241 m^3 of water). Gravity and buoyancy balance; motion is planar.
- Surge drag: MuJoCo's ellipsoid fluid model on a 1.5 x 0.16 x 0.16 m ellipsoid. Its blunt-drag
  force for flow along the axis is C_blunt * rho * pi r_y r_z * v^2 (verified in the tests), so
  C_blunt is set here to give rho*C_d*S/2 = 9 N s^2/m^2 with the paper's numbers.
- Sway and yaw: the same hull gives about 84 N s^2/m^2 of cross-flow drag (9x surge) and an
  angular drag; tail fins add Kutta lift, which keeps the hull directionally stable.
- Added mass: surge and yaw from the ratios of the REMUS 100 model of Prestero (2001, MIT
  thesis, Appendix B: X_udot = -0.93 kg for m = 30.5 kg, N_rdot = -4.88 kg m^2 for
  I_zz = 3.45 kg m^2) scaled to this hull: surge 3.0 % (7.3 kg, in the body mass), yaw 141 %
  of I_zz (256 kg m^2 on top of 181 kg m^2, in I_zz). Sway (221.3 kg) and the sway-yaw coupling
  (87.7 kg m) are the potential-flow added mass of the hull and fin ellipsoids; the
  iout.added_mass plugin (added_mass.c) applies them and every Munk term in body axes, and
  `build_model` turns MuJoCo's own ellipsoid added mass off (it would count the Munk terms
  twice).
- Surge propeller: speed servo F = k_v (ctrl - u) with the drag feedforward in ctrl (set by the
  task once per slot), saturated at rho*C_d*S/2 * V_max^2 so the vehicle reaches V_max and no
  more. Yaw: heading servo (kp, kv) on the yaw joint, saturated at 150 N m.
- Fence: the area's edges are joint limits the hull stops against. A hull held there in a
  current meets the flow broadside, and its Munk moment can out-turn the heading servo while
  the thrust presses it on (a trap that open water, where the hull drifts with the current,
  never sets). So the autopilot turns before it drives: an AUV that starts a slot on the fence
  more than 60 degrees off its heading setpoint holds its thrust for that slot (`fence_hold`).
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from iout_mj import vehicles
from iout_mj.backends.mujoco import added_mass, names
from iout_mj.config import Config
from iout_mj.world.geometry import wrap_angle

added_mass.load()  # the MJCF files name the plugin: MuJoCo must know it before reading them

AUV_DEPTH_M = -10.0
SEABED_DEPTH_M = -30.0
NODE_RADIUS_M = 8.0
THRUST_GAIN_NSPM = vehicles.PAPER_TORPEDO.thrust_gain_nspm
"""k_v of the torpedo's surge speed servo, N per (m/s) of speed error."""
FENCE_BAND_M = 0.5
"""An AUV within this distance of the area's edge is on the fence."""
FENCE_TURN_RAD = float(np.radians(60.0))
"""Heading error beyond which an AUV on the fence holds its thrust for the slot: the trapped
hulls traced in the README were 83 to 88 degrees off their setpoints; a hull in a normal turn
(25 degrees a slot) is never held."""
RUDDER = "rudder"
"""The REMUS's rudder side force (the validation's rudder steps; idle in missions)."""


def mjcf_path(cfg: Config) -> Path:
    """The MJCF file of the config's vehicle."""
    return names.ASSETS_DIR / vehicles.get(cfg.physics.vehicle).mjcf


def hull_drag_nspm2(cfg: Config) -> float:
    """Straight-ahead surge drag / v^2 of the config's hull."""
    return vehicles.hull_drag_nspm2(cfg.physics.vehicle, cfg.motion.drag_factor_nspm2)


def hull_drag_coefficients(cfg: Config, spec: mujoco.MjSpec) -> tuple[float, float]:
    """(C_blunt, C_slender) of the hull ellipsoid that make straight-ahead surge drag
    `hull_drag_nspm2` v^2: along the long axis the blunt drag is C_blunt rho pi r_y r_z v^2 and
    the slender drag C_slender rho pi r_y (r_x - r_z) v^2 (both verified in the tests). The
    MJCF's ratio of the two is kept; a hull without slender drag is all blunt."""
    hull = spec.geom(names.HULL_DRAG_GEOM)
    r_x, r_y, r_z = hull.size
    blunt, slender = hull.fluid_coefs[0], hull.fluid_coefs[1]
    rho = cfg.motion.water_density_kgpm3
    if slender == 0:
        return hull_drag_nspm2(cfg) / (rho * np.pi * r_y * r_z), 0.0
    scale = hull_drag_nspm2(cfg) / (rho * np.pi * r_y * (blunt * r_z + slender * (r_x - r_z)))
    return blunt * scale, slender * scale


def max_thrust_n(cfg: Config) -> float:
    """Thrust limit: the hull's drag at V_max."""
    return hull_drag_nspm2(cfg) * cfg.motion.v_max_mps**2


def thrust_command(speed_mps: np.ndarray, cfg: Config) -> np.ndarray:
    """Servo input for a speed setpoint: setpoint plus the hull's drag feedforward / k_v."""
    gain = vehicles.get(cfg.physics.vehicle).thrust_gain_nspm
    return speed_mps + hull_drag_nspm2(cfg) * np.square(speed_mps) / gain


def fence_hold(
    xy_m: np.ndarray, yaw_rad: np.ndarray, yaw_setpoint_rad: np.ndarray, area_m: tuple[float, float]
) -> np.ndarray:
    """(N,) which AUVs (at (N, 2) positions, unwrapped yaw and yaw setpoints) are on the
    area's fence and more than FENCE_TURN_RAD off their setpoint: their thrust waits a slot."""
    side = np.asarray(area_m, dtype=float)
    on_fence = np.any((xy_m < FENCE_BAND_M) | (xy_m > side - FENCE_BAND_M), axis=-1)
    error = np.abs(wrap_angle(yaw_setpoint_rad - yaw_rad))
    return on_fence & (error > FENCE_TURN_RAD)


def auv_spec(cfg: Config) -> mujoco.MjSpec:
    """The config's AUV alone, its drag and speed servo set from `cfg`."""
    spec = mujoco.MjSpec.from_file(str(mjcf_path(cfg)))
    hull = spec.geom(names.HULL_DRAG_GEOM)
    coefs = list(hull.fluid_coefs)
    coefs[0], coefs[1] = hull_drag_coefficients(cfg, spec)
    hull.fluid_coefs = coefs
    thrust = spec.actuator(names.THRUST)
    f_max = max_thrust_n(cfg)
    gain = vehicles.get(cfg.physics.vehicle).thrust_gain_nspm
    thrust.forcerange = [-f_max, f_max]
    thrust.ctrlrange = [0.0, float(thrust_command(np.array(cfg.motion.v_max_mps), cfg))]
    thrust.gainprm[0] = gain
    thrust.biasprm[2] = -gain
    return spec


def _add_markers(spec: mujoco.MjSpec, cfg: Config) -> None:
    sc = cfg.scenario
    world = spec.worldbody
    ax, ay = sc.area_m
    seabed = spec.geom(names.SEABED_GEOM)
    seabed.pos = [ax / 2, ay / 2, SEABED_DEPTH_M]
    seabed.size = [ax / 2 + 20, ay / 2 + 20, 1]
    for k, (x, y) in enumerate(sc.nodes_m):
        body = world.add_body(name=names.node_name(k), pos=[x, y, SEABED_DEPTH_M])
        body.add_geom(
            name=f"{names.node_name(k)}_marker",
            type=mujoco.mjtGeom.mjGEOM_CYLINDER,
            size=[NODE_RADIUS_M, 2.0, 0],
            pos=[0, 0, 2.0],
            rgba=[0.2, 0.6, 1, 1],
            contype=0,
            conaffinity=0,
            density=0,  # scenery: a massless static body costs no fluid-force work
        )
        body.add_site(name=f"{names.node_name(k)}_antenna", pos=[0, 0, 4.0], size=[0.5, 0, 0])
    dx, dy = sc.dock_center_m
    world.add_geom(
        name=names.DOCK_GEOM,
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        size=[sc.dock_radius_m, 0.2, 0],
        pos=[dx, dy, SEABED_DEPTH_M + 0.5],
        material="dock",
        contype=0,
        conaffinity=0,
    )
    edges = [
        ((ax / 2, 0), (ax / 2, 1)),
        ((ax / 2, ay), (ax / 2, 1)),
        ((0, ay / 2), (1, ay / 2)),
        ((ax, ay / 2), (1, ay / 2)),
    ]
    for i, ((x, y), (hx, hy)) in enumerate(edges):
        world.add_geom(
            name=f"boundary{i}",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[hx, hy, 0.5],
            pos=[x, y, SEABED_DEPTH_M + 0.5],
            material="boundary",
            contype=0,
            conaffinity=0,
        )
    # Top-down camera over the area's centre, high enough to see all of it at fovy = 45 deg.
    height = 0.5 * max(ax, ay) / np.tan(np.radians(22.5)) * 1.08
    world.add_camera(
        name=names.TOP_CAMERA,
        pos=[ax / 2, ay / 2, SEABED_DEPTH_M + height],
        xyaxes=[1, 0, 0, 0, 1, 0],
        fovy=45,
    )


def build_scene(cfg: Config, plugin: bool = True) -> mujoco.MjSpec:
    """The full scene for `cfg`: arena, markers, and N AUVs at their start positions; without
    `plugin`, the AUVs lack their added-mass plugin instances (for MuJoCo Warp, which applies
    the same terms itself)."""
    spec = mujoco.MjSpec.from_file(str(names.ARENA_XML))
    spec.option.timestep = cfg.physics.timestep_s
    spec.option.density = cfg.motion.water_density_kgpm3
    spec.option.wind = [*cfg.physics.current_mps, 0.0]
    _add_markers(spec, cfg)
    for i in range(cfg.scenario.n_auvs):
        frame = spec.worldbody.add_frame(pos=[0.0, 0.0, AUV_DEPTH_M])
        auv = auv_spec(cfg)
        spec.attach(auv, prefix=names.auv_prefix(i), frame=frame)
        if plugin:
            added_mass.attach_instance(spec, auv, names.auv_prefix(i))
        # The area's edges are a fence: joint limits the vehicle stops against.
        for joint, side in (
            (names.JOINT_X, cfg.scenario.area_m[0]),
            (names.JOINT_Y, cfg.scenario.area_m[1]),
        ):
            j = spec.joint(names.auv_prefix(i) + joint)
            j.limited = mujoco.mjtLimited.mjLIMITED_TRUE
            j.range = [0.0, side]
    return spec


def build_model(cfg: Config, plugin: bool = True) -> mujoco.MjModel:
    """Compiled model of `build_scene(cfg, plugin)`; AUVs sit at the origin until the task
    places them. MuJoCo's own added mass of the hulls' fluid ellipsoids is off: the plugin
    applies theirs."""
    model = build_scene(cfg, plugin).compile()
    added_mass.disable_fluid_added_mass(
        model,
        [
            model.geom(names.auv_prefix(i) + g).id
            for i in range(cfg.scenario.n_auvs)
            for g in (names.HULL_DRAG_GEOM, names.FIN_DRAG_GEOM)
        ],
    )
    return model
