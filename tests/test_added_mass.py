"""The hulls' planar added mass (the iout.added_mass MuJoCo plugin) against the analytic
rigid-body-plus-added-mass response: step forces from rest, the Munk and Coriolis terms of a
moving hull, and the state mujoco.rollout carries between calls."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from iout_mj.backends.mujoco import added_mass, names, vehicle
from iout_mj.backends.mujoco.physics import AUVPhysics, Stepper
from iout_mj.config import Config
from iout_mj.scenarios import make_config

# (X_udot, Y_vdot, Y_rdot = N_vdot, N_rdot) as the MJCF files cite them.
COEFFICIENTS = {
    "paper-torpedo": (-7.3, -221.3, 87.7, -256.0),
    "remus100": (-0.93, -35.5, 1.93, -4.88),
}
RIGID = {"paper-torpedo": (240.0, 181.4), "remus100": (30.48, 3.45)}
"""(mass, I_zz) without added mass: the torpedo's 240 kg cylinder, P Table 2.3 / Appendix B."""

YAW = np.radians(30.0)


def _hull(name: str) -> tuple[mujoco.MjModel, mujoco.MjData, list[int], list[int]]:
    """One AUV of vehicle `name` at yaw 30 deg and rest; no actuators, no drag or lift, MuJoCo's
    nor the plugin's (only inertia and the added mass's own terms act)."""
    spec = vehicle.build_scene(Config().with_vehicle(name))
    for instance in spec.plugins:
        instance.config = {k: instance.config[k] for k in ("body", "xudot", "yvdot", "yrdot")}
    model = spec.compile()
    added_mass.disable_fluid_added_mass(
        model, [model.geom(names.auv_prefix(0) + g).id for g in ("hull_drag", "fin_drag")]
    )
    model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_ACTUATION
    model.opt.density = 0.0
    data = mujoco.MjData(model)
    joints = [model.joint(names.auv_prefix(0) + j) for j in ("x", "y", "yaw")]
    dofs = [int(j.dofadr[0]) for j in joints]
    qpos = [int(j.qposadr[0]) for j in joints]
    data.qpos[qpos] = [100.0, 100.0, YAW]
    return model, data, dofs, qpos


def _analytic_mass(name: str) -> np.ndarray:
    """(M_RB + M_A) over (surge, sway, yaw), Fossen (2011) eq. 6.43ff."""
    x_udot, y_vdot, y_rdot, n_rdot = COEFFICIENTS[name]
    mass, izz = RIGID[name]
    return np.diag([mass, mass, izz]) - np.array(
        [[x_udot, 0, 0], [0, y_vdot, y_rdot], [0, y_rdot, n_rdot]]
    )


def _body_accelerations(name: str, force: np.ndarray, substeps: int) -> np.ndarray:
    """(substeps, 3) body-axis accelerations (surge, sway, yaw) under a constant body-axis
    force (surge N, sway N, yaw N m) from rest."""
    model, data, dofs, _ = _hull(name)
    c, s = np.cos(YAW), np.sin(YAW)
    data.qfrc_applied[dofs] = [c * force[0] - s * force[1], s * force[0] + c * force[1], force[2]]
    out = []
    for _ in range(substeps):
        before = data.qvel[dofs].copy()
        mujoco.mj_step(model, data)
        a = (data.qvel[dofs] - before) / model.opt.timestep
        out.append([c * a[0] + s * a[1], -s * a[0] + c * a[1], a[2]])
    return np.array(out)


def test_the_mjcf_coefficients_are_those_cited_and_mujoco_adds_no_mass_of_its_own():
    for name, (x_udot, y_vdot, y_rdot, n_rdot) in COEFFICIENTS.items():
        cfg = Config().with_vehicle(name)
        spec = vehicle.auv_spec(cfg)
        (instance,) = spec.plugins
        config = instance.config
        assert [float(config[k]) for k in ("xudot", "yvdot", "yrdot")] == [x_udot, y_vdot, y_rdot]
        model = vehicle.build_model(cfg.replace(scenario=make_config(2, 7).scenario))
        assert model.nplugin == 2  # one instance per AUV
        body = model.body(names.auv_prefix(1) + names.AUV_BODY).id
        mass, izz = RIGID[name]
        assert model.body_mass[body] == pytest.approx(mass - x_udot, abs=0.01)
        assert model.body_inertia[body, 2] == pytest.approx(izz - n_rdot, abs=0.1)
        assert not model.geom_fluid[:, 6:].any()


@pytest.mark.parametrize("name", sorted(COEFFICIENTS))
@pytest.mark.parametrize(
    ("axis", "magnitude"), [(0, 10.0), (1, 10.0), (2, 5.0)], ids=["surge", "sway", "yaw"]
)
def test_step_force_from_rest_gives_the_analytic_acceleration(name, axis, magnitude):
    force = np.zeros(3)
    force[axis] = magnitude
    # from the second substep on: the plugin knows a force one substep after it starts
    got = _body_accelerations(name, force, 10)[1:].mean(axis=0)
    exact = np.linalg.solve(_analytic_mass(name), force)
    np.testing.assert_allclose(got, exact, rtol=0.02, atol=0.01 * abs(exact).max())
    # F / (m + m_v) and M / (I_zz + I_A) alone ignore the coupling: they are 0.7 % (REMUS) and
    # 4.0 % (torpedo) off the exact solve in sway and in yaw; surge has no coupling
    if axis == 0:
        x_udot, *_ = COEFFICIENTS[name]
        assert got[0] == pytest.approx(magnitude / (RIGID[name][0] - x_udot), rel=1e-6)


@pytest.mark.parametrize("name", sorted(COEFFICIENTS))
def test_sway_force_turns_the_hull_as_the_coupling_says(name):
    """Y_rdot = N_vdot > 0: a sway force to port yaws the hull to port (counterclockwise), at
    r_dot = -M_A[v, r] F / det of the sway-yaw block."""
    m = _analytic_mass(name)
    got = _body_accelerations(name, np.array([0.0, 10.0, 0.0]), 5)[1:].mean(axis=0)
    expected = -m[1, 2] * 10.0 / (m[1, 1] * m[2, 2] - m[1, 2] ** 2)
    assert expected > 0
    assert got[2] == pytest.approx(expected, rel=0.02)
    assert got[1] == pytest.approx(m[2, 2] * 10.0 / (m[1, 1] * m[2, 2] - m[1, 2] ** 2), rel=0.02)


@pytest.mark.parametrize("name", sorted(COEFFICIENTS))
def test_a_moving_hull_feels_the_munk_and_coriolis_terms(name):
    """No force but the added mass's own: nu_dot = M^-1 (-C_RB(nu) nu - C_A(nu) nu), with the
    water-relative velocity (a current must not change it)."""
    model, data, dofs, _ = _hull(name)
    model.opt.wind[:2] = [0.3, -0.2]
    u, v, r = 1.5, 0.2, 0.1
    c, s = np.cos(YAW), np.sin(YAW)
    data.qvel[dofs] = [c * u - s * v + 0.3, s * u + c * v - 0.2, r]
    before = data.qvel[dofs].copy()
    mujoco.mj_step(model, data)
    a = (data.qvel[dofs] - before) / model.opt.timestep
    # the body-axis derivative: the world acceleration rotated, plus the frame's rotation
    got = np.array([c * a[0] + s * a[1] + r * v, -s * a[0] + c * a[1] - r * u, a[2]])
    x_udot, y_vdot, y_rdot, _ = COEFFICIENTS[name]
    m_u, m_v, m_vr = -x_udot, -y_vdot, -y_rdot
    mass, _ = RIGID[name]
    c_rb = np.array([-mass * r * v, mass * r * u, 0.0])
    c_a = np.array([-(m_v * v + m_vr * r) * r, m_u * u * r, (m_v - m_u) * u * v + m_vr * u * r])
    exact = np.linalg.solve(_analytic_mass(name), -(c_rb + c_a))
    np.testing.assert_allclose(got, exact, rtol=1e-6, atol=1e-9)


def test_rollout_carries_the_plugin_state_across_calls_and_threads():
    cfg = make_config(2, 7).with_vehicle("remus100")

    def fly(chunks: list[int], nthread: int) -> np.ndarray:
        physics = [AUVPhysics.from_config(cfg) for _ in range(3)]
        for j, p in enumerate(physics):
            p.set_poses(
                np.array([[100.0 + j, 200.0], [300.0, 300.0]]),
                np.array([0.3, 1.0]),
                np.array([1.0, 1.5]),
            )
            p.set_commands(np.array([1.0 + 0.2 * j, 0.2]), np.array([2.0, 1.0]))
        stepper = Stepper(nthread)
        for n in chunks:
            stepper.step(physics, n)
        out = np.stack([np.concatenate([p.data.qpos, p.data.ptr.plugin_state]) for p in physics])
        stepper.close()
        for p in physics:
            p.free()
        return out

    one = fly([200], 0)
    np.testing.assert_array_equal(fly([50] * 4, 0), one)
    np.testing.assert_array_equal(fly([200], 2), one)
    assert np.abs(one[:, -20:]).max() > 0  # the plugin ran


@pytest.mark.slow
def test_warp_applies_the_same_added_mass_and_hull_forces_to_the_remus():
    """MuJoCo Warp runs no C plugin: its kernels apply the same terms (two slots, N = 2, K = 7,
    on Warp's CPU device; the torpedo's case is tests/test_warp.py)."""
    pytest.importorskip("mujoco_warp")
    from iout_mj.backends.mujoco.warp_stepper import WarpStepper
    from iout_mj.envs.batch import MissionBatch

    config = {"physics": {"current_jitter_mps": 0.2, "vehicle": "remus100"}}
    c = MissionBatch(4, "mujoco", 2, 7, "random", config, seed=3)
    w = MissionBatch(4, "mujoco", 2, 7, "random", config, seed=3)
    w.stepper = WarpStepper(device="cpu")
    c.restart()
    w.restart()
    rng = np.random.RandomState(2)
    for tolerance_m in (2e-4, 5e-3):  # as tests/test_warp.py: float32 drifts in slot 2
        a = np.stack(
            [
                np.concatenate([[rng.randint(11), rng.randint(7), rng.randint(7), 1] for _ in "ab"])
                for _ in range(4)
            ]
        )
        c.step(a)
        w.step(a)
        qc = np.stack([p.data.qpos for p in c.physics])
        qw = np.stack([p.data.qpos for p in w.physics])
        assert np.abs(qc - qw).max() < tolerance_m
        # the hulls' other forces come back for the next slot (float32: within 0.1 N of the
        # thrust's 10 N)
        states = [np.stack([p.data.ptr.plugin_state for p in b.physics]) for b in (c, w)]
        assert np.abs(states[1]).max() > 0
        np.testing.assert_allclose(states[1][..., :3], states[0][..., :3], atol=0.1)
    c.close()
    w.close()
