"""The vehicle registry (physics.vehicle) and the REMUS 100 hull against published figures."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from iout_mj import vehicles
from iout_mj.backends.kinematic import KinematicEnvironment
from iout_mj.backends.mujoco import names, vehicle
from iout_mj.backends.mujoco.task import make_environment
from iout_mj.config import Config
from iout_mj.experiments import energy_validation as ev
from iout_mj.schema import ConfigError

REMUS = Config().with_vehicle("remus100")


def test_an_unknown_vehicle_is_refused_naming_the_accepted_ones():
    with pytest.raises(ConfigError, match=r"physics\.vehicle") as err:
        Config.from_dict({"physics": {"vehicle": "remus"}})
    assert "'paper-torpedo', 'remus100'" in str(err.value)
    with pytest.raises(ConfigError, match="paper-torpedo, remus100"):
        vehicles.get("torpedo")


def test_a_config_file_vehicle_sets_its_motion_unless_the_file_does():
    cfg = Config.from_dict({"physics": {"vehicle": "remus100"}, "motion": {"v_max_mps": 2.0}})
    assert cfg.motion.v_max_mps == 2.0
    assert cfg.motion.water_density_kgpm3 == 1030.0
    assert cfg.motion.drag_factor_nspm2 == pytest.approx(1.62)  # fitted to X_uu
    assert REMUS.motion.v_max_mps == 2.5
    assert Config.from_dict({}).physics.vehicle == "paper-torpedo"


def _hull_force(cfg: Config, qvel: list[float]) -> np.ndarray:
    model = vehicle.build_model(cfg)
    data = mujoco.MjData(model)
    dofs = [model.joint(names.auv_prefix(0) + j).dofadr[0] for j in ("x", "y", "yaw")]
    data.qvel[dofs] = qvel
    mujoco.mj_forward(model, data)
    return data.qfrc_fluid[dofs]


@pytest.mark.parametrize("v", [0.5, 1.54, 2.5])
def test_remus_surge_drag_is_prestero_x_uu(v):
    assert -_hull_force(REMUS, [v, 0.0, 0.0])[0] == pytest.approx(1.62 * v**2, rel=1e-9)


def test_remus_coefficients_behind_the_mjcf_comments():
    """The per-unit-coefficient forces the MJCF's comments use to size its fluid coefficients;
    the body's lift is the plugin's, not MuJoCo's."""
    hull = vehicle.auv_spec(REMUS).geom(names.HULL_DRAG_GEOM)
    blunt, slender, angular, kutta, _ = hull.fluid_coefs
    r = _hull_force(REMUS, [0.0, 0.0, 1.0])[2]
    assert r == pytest.approx(-94.0, rel=0.01)  # N_rr
    assert angular == pytest.approx(2.92)
    assert kutta == 0.0
    assert slender / blunt == pytest.approx(0.00789 / 0.0078)


def test_remus_sway_and_lift_are_prestero_s_combined_coefficients():
    """In steady sideslip the hull's hydrodynamic force is P Appendix B's: surge X_uu u^2,
    sway Y_uv u v + Y_vv v|v|, yaw N_uv u v + N_vv v|v| (MuJoCo's drag and fin lift, and the
    plugin's cross-flow drag, body lift and Munk moment), read off the acceleration: M nu_dot
    with M = M_RB + M_A (no rotation: no other Coriolis term)."""
    model = vehicle.build_model(REMUS)
    model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_ACTUATION
    data = mujoco.MjData(model)
    dofs = [model.joint(names.auv_prefix(0) + j).dofadr[0] for j in ("x", "y", "yaw")]
    u, v = 1.5, 0.03
    data.qvel[dofs] = [u, v, 0.0]
    mujoco.mj_forward(model, data)
    data.plugin_state[:3] = data.qfrc_fluid[dofs]  # the plugin's F_o, as after a substep here
    mujoco.mj_forward(model, data)
    mass = np.array([[31.41, 0.0, 0.0], [0.0, 30.48 + 35.5, -1.93], [0.0, -1.93, 8.33]])
    x, y, n = mass @ data.qacc[dofs]
    assert x == pytest.approx(-1.62 * u**2, rel=0.01)
    assert y == pytest.approx(-28.6 * u * v - 1310 * v * abs(v), rel=0.02)
    assert n == pytest.approx(-24.0 * u * v - 3.18 * v * abs(v), rel=0.02)


def test_remus_steady_speed_under_prestero_thrust_and_its_rudder_step():
    assert ev.steady_speed_under_thrust(REMUS, ev.PRESTERO_THRUST_N) == pytest.approx(
        ev.PRESTERO_SPEED_MPS, rel=0.005
    )
    turn = ev.rudder_step(REMUS)
    published = ev.PRESTERO_TURN
    assert turn["surge_mps"] == pytest.approx(published["surge_mps"], rel=0.06)
    assert turn["yaw_rate_dps"] == pytest.approx(published["yaw_rate_dps"], rel=0.08)
    assert turn["sway_mps"] == pytest.approx(published["sway_mps"], rel=0.2)
    diameter = ev.turning_diameter_m(
        float(np.hypot(published["surge_mps"], published["sway_mps"])), published["yaw_rate_dps"]
    )
    assert turn["turning_diameter_m"] == pytest.approx(diameter, rel=0.03)


def test_both_backends_fly_the_remus_at_its_own_v_max():
    cfg = REMUS.replace(scenario=REMUS.scenario.__class__(horizon_slots=3))
    kin = KinematicEnvironment(cfg, seed=0)
    kin.reset()
    env = make_environment(cfg, seed=0)
    env.reset()
    action = kin.action_spec().maximum  # fastest, hardest turn
    for _ in range(3):
        kin.step(action)
        env.step(action)
    for m in (kin.mission, env.task.mission):
        assert (m.state.speeds_mps <= 2.5 + 1e-6).all()
        assert (m.state.speed_sp <= 2.5 + 1e-9).all()
    assert env.physics.cfg.physics.vehicle == "remus100"
