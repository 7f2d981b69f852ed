"""The gymnasium environment on both backends."""

import dataclasses
import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from iout_mj.backends.registry import SINGLE_ENV_BACKENDS
from iout_mj.envs import ENV_ID, MultiAUVEnv
from iout_mj.experiments.bench_training import peak_rss_mb
from iout_mj.scenarios import make_config
from iout_mj.schema import ConfigError
from iout_mj.world.geometry import slot_velocity_mps, unit_xy, wrap_angle

BACKENDS = list(SINGLE_ENV_BACKENDS)  # the registry's one-env backends
METRIC_KEYS = {
    "mean_aoi",
    "objective",
    "jain",
    "delivered_bits",
    "propulsion_energy_j",
    "min_separation_m",
    "docked",
    "mission_slots",
    "collisions",
}


def make(backend, **kw):
    return gym.make(ENV_ID, backend=backend, **kw)


def rollout(env, seed, actions):
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for a in actions:
        obs, r, term, trunc, info = env.step(a)
        out.append((obs, r, term, trunc, info.get("metrics")))
        if term or trunc:
            break
    return out


def scenario(cfg, **changes):
    return cfg.replace(scenario=dataclasses.replace(cfg.scenario, **changes))


@pytest.mark.parametrize("backend", BACKENDS)
def test_checkers(backend):
    env = make(backend, n_auvs=2, n_nodes=7)
    check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(env.unwrapped, warn=True)


@pytest.mark.parametrize("backend", BACKENDS)
def test_spaces_and_finite_observations(backend):
    env = make(backend, n_auvs=3, n_nodes=13)
    assert list(env.action_space.nvec) == [11, 7, 13, 13] * 3
    obs, _ = env.reset(seed=1)
    assert obs.shape == (2 * 3 + 2 * 3 + 3 + 3 + 13 + 13 + 39 + 3 + 1,)
    env.action_space.seed(1)
    done = False
    while not done:
        obs, r, term, trunc, info = env.step(env.action_space.sample())
        assert env.observation_space.contains(obs)
        assert np.isfinite(r)
        done = term or trunc
    assert set(info["metrics"]) >= METRIC_KEYS
    assert info["metrics"]["mission_slots"] <= 55


@pytest.mark.parametrize("backend", BACKENDS)
def test_same_seed_same_trajectory(backend):
    env = make(backend)
    rng = np.random.default_rng(3)
    actions = [rng.integers(0, env.action_space.nvec) for _ in range(55)]
    a, b = rollout(env, 7, actions), rollout(env, 7, actions)
    c = rollout(env, 8, actions)
    assert np.array_equal(a[0], b[0]) and not np.array_equal(a[0], c[0])
    for x, y in zip(a[1:], b[1:], strict=False):
        assert np.array_equal(x[0], y[0]) and x[1:4] == y[1:4] and x[4] == y[4]


@pytest.mark.parametrize("backend", BACKENDS)
def test_pickle_round_trip(backend):
    env = make(backend, n_auvs=1, n_nodes=13).unwrapped
    clone = pickle.loads(pickle.dumps(env))
    actions = [np.array([6, 4, 1, 1])] * 5
    a, b = rollout(env, 2, actions), rollout(clone, 2, actions)
    assert all(np.array_equal(x[0], y[0]) for x, y in zip(a[1:], b[1:], strict=False))


@pytest.mark.parametrize("backend", BACKENDS)
def test_first_slot_reward_by_hand(backend):
    """One AUV from (50, 50) due east at 1 m/s (both backends end the slot at (75, 50)),
    charging and collecting from node 0 at (100, 100): every term and the reward by hand."""
    cfg = scenario(make_config(1, 7), start_jitter_m=0.0, start_heading_jitter_deg=0.0)
    env = make(backend, config=cfg)
    env.reset(seed=0)
    _, reward, *_, info = env.step(np.array([5, 3, 0, 0]))
    dock = np.hypot(830.0 - 50.0, 830.0 - 50.0)
    progress = 0.02 * (dock - np.hypot(830.0 - 75.0, 830.0 - 50.0))  # 25 m east
    assert info["reward_terms"] == {
        "docking_progress": pytest.approx(progress, rel=1e-6),
        "aoi": pytest.approx(-0.1 * 2.0),  # every node aged from 1 to 2 (node 0: 1 of 3 updates)
        "fairness": 0.0,  # 1 delivery, not more than 3
        "boundary": 0.0,
        "stall": 0.0,
        # node 0 stores 0.1 J; the uplink from ~56 m needs ~0.6 mJ: tanh(~160) = 1, x 2.0 / N
        "energy_margin": pytest.approx(2.0),
        "infeasible_uplink": 0.0,
        "collision": 0.0,  # one AUV
        "docking": 0.0,
        "deadline": 0.0,  # 1103 m from the dock, 54 x 25 s x 2 m/s = 2700 m of reach
        "undocked_at_end": 0.0,
        "aoi_after_mission": 0.0,
    }
    assert reward == pytest.approx(progress - 0.2 + 2.0, rel=1e-6)


@pytest.mark.parametrize("backend", BACKENDS)
def test_bad_actions(backend):
    env = make(backend, n_auvs=2, n_nodes=7)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(7, dtype=int))
    with pytest.raises(
        ValueError, match=r"AUV 1: aet_node index 7 is out of range; accepted 0 to 6"
    ):
        env.step(np.array([5, 3, 0, 0, 5, 3, 7, 0]))
    with pytest.raises(ValueError, match=r"AUV 0: heading index -1"):
        env.step(np.array([-1, 3, 0, 0, 5, 3, 0, 0]))
    with pytest.raises(ValueError, match="non-integer"):
        env.step(np.array([5.5, 3, 0, 0, 5, 3, 0, 0]))
    env.step(np.array([5.0, 3, 0, 0, 5, 3, 0, 0]))  # integral floats are accepted


def test_bad_env_arguments(tmp_path):
    with pytest.raises(ValueError, match="backend='bullet'"):
        make("bullet")
    with pytest.raises(ConfigError, match="layout"):
        gym.make(ENV_ID, layout="grid")
    with pytest.raises(ConfigError, match="unknown key"):
        gym.make(ENV_ID, config={"scenario": {"n_robots": 2}})
    with pytest.raises(ConfigError, match="n_auvs=9"):
        gym.make(ENV_ID, n_auvs=9)
    with pytest.raises(ValueError, match="render_mode"):
        MultiAUVEnv(render_mode="human")


@pytest.mark.parametrize("backend", BACKENDS)
def test_network_and_energy_bookkeeping(backend):
    cfg = scenario(make_config(1, 7), start_jitter_m=0.0, start_heading_jitter_deg=0.0)
    env = make(backend, config=cfg)
    env.reset(seed=0)
    m = env.unwrapped.mission
    # straight on at 1 m/s from (50, 50): charge and collect from node 0 at (100, 100)
    _, _, _, _, _info = env.step(np.array([5, 3, 0, 0]))
    assert m.network.deliveries[0] == 1 and m.network.deliveries[1:].sum() == 0
    assert m.network.aoi[0] == 2.0 and m.network.aoi[1] == 2.0
    assert m.network.energy_j[0] > cfg.network.node_initial_energy_j  # AET outweighs uplink
    expected = (9.0 * 1.0**3 / 0.7 + 40.0) * 25.0
    assert m.state.propulsion_energy_j[0] == pytest.approx(expected, rel=0.02)
    for _ in range(2):
        env.step(np.array([5, 3, 0, 0]))
    assert m.network.aoi[0] == 1.0  # third delivery resets


def test_kinematic_slot_holds_the_ground_speed_and_drifts_across_with_the_current():
    cfg = scenario(make_config(2, 7), start_jitter_m=0.0, start_heading_jitter_deg=0.0)
    cfg = cfg.replace(physics=dataclasses.replace(cfg.physics, current_mps=(0.1, -0.2)))
    env = make("kinematic", config=cfg)
    env.reset(seed=0)
    m = env.unwrapped.mission
    start = m.state.positions_m.copy()
    env.step(np.array([8, 5, 0, 0, 2, 1, 1, 1]))  # AUV 0: +15 deg, +0.267 m/s; AUV 1: -15, -0.267
    theta = np.radians([15.0, -15.0])  # (2 j / 10 - 1) * 25 deg from heading 0
    v = 1.0 + np.array([1.0, -1.0]) * 0.4 * 2 / 3  # (2 j / 6 - 1) * 0.4 m/s from 1 m/s
    heading = np.stack([np.cos(theta), np.sin(theta)], -1)
    along = heading @ [0.1, -0.2]  # the current along each heading
    across = np.array([0.1, -0.2]) - along[:, None] * heading
    expected = start + (v[:, None] * heading + across) * 25.0
    np.testing.assert_allclose(m.state.positions_m, expected, atol=1e-9)
    np.testing.assert_allclose(m.state.headings_rad, theta, atol=1e-12)
    water = v - along  # the speed through the water along the heading
    drag_w = 0.5 * 1000.0 * 0.006 * 3.0 * water**3 / 0.7  # rho C_d S v^3 / (2 eta)
    np.testing.assert_allclose(m.state.propulsion_energy_j, drag_w * 25.0 + 40.0 * 25.0)


def test_kinematic_slot_stops_at_v_max_through_the_water():
    """Against a current along the heading the ground speed is at most V_max minus it."""
    cfg = scenario(make_config(1, 7), start_jitter_m=0.0, start_heading_jitter_deg=0.0)
    cfg = cfg.replace(physics=dataclasses.replace(cfg.physics, current_mps=(-0.5, 0.0)))
    cfg = cfg.replace(motion=dataclasses.replace(cfg.motion, v_max_mps=1.2, initial_speed_mps=1.2))
    env = make("kinematic", config=cfg)
    env.reset(seed=0)
    m = env.unwrapped.mission
    start = m.state.positions_m.copy()
    env.step(np.array([5, 3, 0, 0]))  # hold heading 0 (east) and 1.2 m/s
    np.testing.assert_allclose(m.state.positions_m - start, [[(1.2 - 0.5) * 25.0, 0.0]], atol=1e-9)
    drag_w = 0.5 * 1000.0 * 0.006 * 3.0 * 1.2**3 / 0.7
    np.testing.assert_allclose(m.state.propulsion_energy_j, drag_w * 25.0 + 40.0 * 25.0)


def test_slot_velocity_mirrors_the_kinematic_slot():
    """`geometry.slot_velocity_mps` (the shield's model) moves an AUV as the compiled slot does,
    with the thrust limit binding in some slots (V_max 1.5 m/s against up to 1 m/s)."""
    cfg = scenario(make_config(3, 7), start_jitter_m=0.0)
    cfg = cfg.replace(
        physics=dataclasses.replace(cfg.physics, current_mps=(-0.6, 0.8)),
        motion=dataclasses.replace(cfg.motion, v_max_mps=1.5),
    )
    env = make("kinematic", config=cfg)
    env.reset(seed=0)
    m = env.unwrapped.mission
    rng = np.random.default_rng(0)
    checked = limited = 0
    for _ in range(12):
        start = m.state.positions_m.copy()
        env.step(rng.integers(0, env.action_space.nvec))
        velocity = slot_velocity_mps(m.state.heading_sp, m.state.speed_sp, (-0.6, 0.8), 1.5)
        moved = np.any(m.state.positions_m != start, axis=1)
        np.testing.assert_allclose(
            m.state.positions_m[moved], start[moved] + 25.0 * velocity[moved], atol=1e-9
        )
        along = unit_xy(m.state.heading_sp) @ [-0.6, 0.8]
        limited += int(np.sum(moved & (m.state.speed_sp > 1.5 + along)))
        checked += int(moved.sum())
    assert checked >= 30 and limited >= 1


@pytest.mark.parametrize("backend", BACKENDS)
def test_boundary_attempt_is_penalised_and_kept_inside(backend):
    cfg = scenario(
        make_config(1, 7),
        start_jitter_m=0.0,
        start_heading_jitter_deg=0.0,
        start_heading_rad=float(np.pi),
        starts_m=((40.0, 500.0),),
    )
    env = make(backend, config=cfg)
    env.reset(seed=0)
    terms = []
    for _ in range(3):
        _, _, _, _, info = env.step(np.array([5, 3, 0, 0]))  # keep going west at 1 m/s
        terms.append(info["reward_terms"]["boundary"])
    assert terms[0] == 0.0 and terms[1] == -20.0
    x = env.unwrapped.mission.state.positions_m[0, 0]
    assert -0.05 <= x <= 16.0  # the fence is a (stiff) soft constraint


@pytest.mark.parametrize("backend", BACKENDS)
def test_docking_terminates_with_bonus(backend):
    cfg = scenario(
        make_config(1, 7),
        starts_m=((745.0, 830.0),),
        start_jitter_m=0.0,
        start_heading_jitter_deg=0.0,
    )
    env = make(backend, config=cfg)
    env.reset(seed=0)
    _, _r, term, trunc, info = env.step(np.array([5, 3, 0, 0]))
    assert term and not trunc
    assert info["reward_terms"]["docking"] == 70.0  # 60 first entry + 10 all docked
    assert info["metrics"]["docked"] == [True]
    # the 54 slots left: every node ages from AoI 2 (after this slot) without service
    ages = np.minimum(2.0 + np.arange(1, 55), 50.0)
    assert info["reward_terms"]["aoi_after_mission"] == pytest.approx(-0.1 * ages.sum())
    m = info["metrics"]
    assert m["mean_aoi"] == 2.0
    assert m["mean_aoi_horizon"] == pytest.approx((2.0 + ages.sum()) / 55)


@pytest.mark.parametrize("backend", BACKENDS)
def test_truncation_at_horizon(backend):
    env = make(backend, config=scenario(make_config(2, 7), horizon_slots=3))
    env.reset(seed=0)
    steps = [env.step(np.array([5, 3, 0, 0, 5, 3, 1, 1])) for _ in range(3)]
    assert [s[2:4] for s in steps] == [(False, False), (False, False), (False, True)]
    terms = [s[4]["reward_terms"] for s in steps]
    assert [t["undocked_at_end"] for t in terms] == [0.0, 0.0, -200.0]  # both missed the dock
    # deadline shaping: 3-slot horizon, v_ref 2 m/s: the dock (~1000 m) is out of reach
    m = env.unwrapped.mission
    assert all(t["deadline"] < 0 for t in terms)
    start_dist = np.linalg.norm(m.log.positions_m[0] - m.dock_m, axis=1)
    slack_start = np.maximum(0.0, start_dist - 2.0 * 3 * 25)  # potential telescopes
    total = sum(t["deadline"] for t in terms)
    assert total == pytest.approx(0.1 * float(np.sum(slack_start - m.state.dock_dist_m)))


@pytest.mark.parametrize("backend", BACKENDS)
def test_collision_penalty(backend):
    cfg = scenario(
        make_config(2, 7),
        starts_m=((300.0, 300.0), (300.0, 330.0)),
        start_jitter_m=0.0,
        start_heading_jitter_deg=0.0,
    )
    env = make(backend, config=cfg)
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([5, 3, 0, 0, 5, 3, 1, 1]))
    d = 30.0  # parallel tracks 30 m apart
    expected = -4.0 * (1 - np.exp(-((100 - d) ** 2) / (2 * 20.0**2)))
    assert info["reward_terms"]["collision"] == pytest.approx(expected, rel=0.02)
    far = scenario(cfg, starts_m=((100.0, 100.0), (600.0, 100.0)))
    env = make(backend, config=far)
    env.reset(seed=0)
    assert env.step(np.array([5, 3, 0, 0, 5, 3, 1, 1]))[4]["reward_terms"]["collision"] == 0.0


def test_kinematic_and_physics_agree_on_gentle_manoeuvres():
    cfg = scenario(make_config(2, 7), start_jitter_m=0.0, start_heading_jitter_deg=0.0)
    envs = {b: make(b, config=cfg) for b in BACKENDS}
    pattern = [6, 5, 5, 4, 5, 6, 5, 5, 4, 5]  # +-5 deg turns; speed +0.13 m/s then hold
    speeds = [4, 4, 3, 3, 3, 3, 3, 3, 3, 3]
    for env in envs.values():
        env.reset(seed=0)
    for h, s in zip(pattern, speeds, strict=False):
        a = np.array([h, s, 0, 0, h, s, 3, 3])
        for env in envs.values():
            env.step(a)
    kin, phy = (envs[b].unwrapped.mission for b in BACKENDS)
    path = 10 * 25 * 1.4
    assert np.abs(kin.state.positions_m - phy.state.positions_m).max() < 0.04 * path
    # the servos track the commanded headings: measured headings agree within 3 deg
    assert np.abs(wrap_angle(kin.state.headings_rad - phy.state.headings_rad)).max() < 0.05
    # same bookkeeping rules: the deliveries differ only if positions put a node out of reach
    assert np.array_equal(kin.network.deliveries, phy.network.deliveries)


def test_diverged_physics_ends_episode_with_error():
    env = make("mujoco")
    _obs0, _ = env.reset(seed=0)
    env.unwrapped.physics.data.qvel[:] = 1e200
    obs, _r, term, _trunc, info = env.step(np.array([5, 3, 0, 0, 5, 3, 0, 0]))
    assert term and "error" in info and "metrics" in info
    assert np.all(np.isfinite(obs))


def test_random_layout_per_episode():
    env = make("kinematic", n_auvs=1, n_nodes=9, layout="random")
    env.reset(seed=1)
    a = env.unwrapped.mission.network.nodes_m.copy()
    env.reset(seed=2)
    b = env.unwrapped.mission.network.nodes_m.copy()
    env.reset(seed=1)
    assert not np.array_equal(a, b)
    assert np.array_equal(a, env.unwrapped.mission.network.nodes_m)


def test_one_env_stays_under_200_mb():
    # VmHWM (peak resident set) of a child process alone (the benchmark's probe).
    rss_mb = peak_rss_mb(
        "import gymnasium as gym, numpy as np, iout_mj\n"
        "env = gym.make('iout_mj/MultiAUV-v0', backend='mujoco', n_auvs=4, n_nodes=13)\n"
        "env.reset(seed=0)\n"
        "for _ in range(55): env.step(env.action_space.sample())\n"
    )
    assert rss_mb < 200, rss_mb
