"""The batched kinematic backend: one Mission over B environments, served as an SB3 VecEnv."""

import dataclasses

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

from iout_mj.backends.kinematic import move
from iout_mj.envs import ENV_ID, KinematicVecEnv, PhysicsVecEnv
from iout_mj.envs.gym_vector import MultiAUVVectorEnv
from iout_mj.envs.scenario_vec_env import ScenarioVecEnv
from iout_mj.mission import ActionError, Mission
from iout_mj.mission.rules import unserved_aoi_sum
from iout_mj.runtime import usable_cpus


def docked_start(cfg):
    """No start jitter and both AUVs starting 100 m west of the dock centre (radius 70 m),
    heading east: every reset is the same, and AUVs that fly straight on at 1.4 m/s dock
    after one slot (so that episodes end at different steps)."""
    sc = dataclasses.replace(
        cfg.scenario,
        start_jitter_m=0.0,
        start_heading_jitter_deg=0.0,
        starts_m=((730.0, 830.0), (730.0, 835.0)),
    )
    return cfg.replace(scenario=sc)


def assert_batch_matches_independent_envs(venv, backend, cfg, rng, steps):
    b = venv.num_envs
    singles = [gym.make(ENV_ID, backend=backend, config=cfg) for _ in range(b)]
    obs = venv.reset()
    for e, env in enumerate(singles):
        np.testing.assert_array_equal(obs[e], env.reset(seed=e)[0])
    ends = np.zeros(b, dtype=int)
    for _ in range(steps):
        actions = rng.integers(0, venv.action_space.nvec, size=(b, venv.action_space.shape[0]))
        actions[0, 0::4] = 5  # env 0 flies straight on (dtheta 0) ...
        actions[0, 1::4] = 6  # ... speeding up to 1.4 m/s: it docks after one slot
        obs, rewards, dones, infos = venv.step(actions)
        for e, env in enumerate(singles):
            o, r, term, trunc, info = env.step(actions[e])
            assert rewards[e] == pytest.approx(r, rel=1e-6, abs=1e-6)
            assert dones[e] == (term or trunc)
            if dones[e]:
                ends[e] += 1
                np.testing.assert_allclose(infos[e]["terminal_observation"], o, atol=1e-6)
                assert infos[e]["TimeLimit.truncated"] == trunc
                for key, value in info["metrics"].items():
                    assert infos[e]["metrics"][key] == pytest.approx(value), key
                o, _ = env.reset()
            np.testing.assert_allclose(obs[e], o, atol=1e-6)
    assert ends[0] == steps  # one-slot episodes
    assert ends[1:].min() > 0 and ends[1:].max() < steps  # others end later, when they may


def test_kinematic_batch_matches_independent_environments(cfg, rng):
    cfg = docked_start(cfg)
    assert_batch_matches_independent_envs(
        KinematicVecEnv(4, config=cfg), "kinematic", cfg, rng, 120
    )


def test_physics_batch_on_two_threads_matches_independent_environments(cfg, rng):
    cfg = docked_start(cfg)
    venv = PhysicsVecEnv(3, config=cfg, nthread=min(2, usable_cpus()))  # 2 where allowed
    assert_batch_matches_independent_envs(venv, "mujoco", cfg, rng, 70)
    venv.close()


def test_diverged_physics_ends_only_its_environment(cfg, rng):
    venv = PhysicsVecEnv(3, config=cfg, seed=0)
    venv.reset()
    venv.physics[1].data.qvel[:] = 1e200
    act = rng.integers(0, venv.action_space.nvec, size=(3, venv.action_space.shape[0]))
    obs, rewards, dones, infos = venv.step(act)
    assert dones.tolist() == [False, True, False]
    assert "diverged" in infos[1]["error"] and "metrics" in infos[1]
    assert rewards[1] == 0.0 and np.isfinite(obs).all()
    assert venv.mission.state.slot.tolist() == [1, 0, 1]  # env 1 restarted, the others go on
    with pytest.raises(ValueError, match="nthread=-1"):
        PhysicsVecEnv(2, config=cfg, nthread=-1)
    venv.close()


def test_partial_reset_only_touches_masked_rows(cfg):
    m = Mission(cfg, n_envs=4)
    rng = np.random.RandomState(0)
    m.reset(rng)
    for _ in range(3):
        move(m, np.tile(m.actions.high // 2, (4, 1)))
    before = m.observation()
    mask = np.array([True, False, True, False])
    m.reset(rng, mask)
    after = m.observation()
    for name in before:
        np.testing.assert_array_equal(after[name][~mask], before[name][~mask])
    assert m.state.slot.tolist() == [0, 3, 0, 3]
    assert not np.array_equal(m.state.positions_m[0], m.state.positions_m[2])  # one draw per row


def test_seeding_reproduces_the_batch(cfg, rng):
    a, b = KinematicVecEnv(3, config=cfg, seed=7), KinematicVecEnv(3, config=cfg)
    b.seed(7)
    np.testing.assert_array_equal(a.reset(), b.reset())
    for _ in range(60):
        act = rng.integers(0, a.action_space.nvec, size=(3, a.action_space.shape[0]))
        oa, ra, done_a, _ = a.step(act)
        ob, rb, done_b, _ = b.step(act)
        np.testing.assert_array_equal(oa, ob)
        np.testing.assert_array_equal(ra, rb)
        np.testing.assert_array_equal(done_a, done_b)


def test_bad_batched_actions_name_env_auv_and_range(cfg):
    venv = KinematicVecEnv(3, config=cfg)
    venv.reset()
    good = np.zeros((3, 8), dtype=np.int64)
    with pytest.raises(ActionError, match=r"shape \(8,\); accepted 3 rows"):
        venv.step(good[0])
    bad = good.copy()
    bad[2, 6] = 7  # env 2, AUV 1, aet_node; K = 7
    with pytest.raises(ActionError, match=r"env 2, AUV 1: aet_node index 7 .* accepted 0 to 6"):
        venv.step(bad)
    with pytest.raises(ValueError, match="n_envs=0"):
        KinematicVecEnv(0, config=cfg)


def test_ppo_trains_on_the_vec_env(cfg):
    venv = VecNormalize(VecMonitor(KinematicVecEnv(4, config=cfg, seed=0)))
    model = PPO("MlpPolicy", venv, n_steps=32, batch_size=64, n_epochs=1, device="cpu", seed=0)
    before = [p.detach().clone() for p in model.policy.parameters()]
    model.learn(4 * 32 * 2)
    episodes = list(model.ep_info_buffer)  # the monitor saw whole episodes end
    assert episodes and all(1 <= e["l"] <= 55 and np.isfinite(e["r"]) for e in episodes)
    assert any(not (a == b).all() for a, b in zip(before, model.policy.parameters(), strict=True))
    assert np.isfinite(venv.obs_rms.mean).all() and venv.obs_rms.count > 4 * 32 * 2


def test_aoi_booked_after_an_early_end_matches_slot_by_slot_ageing(cfg):
    m = Mission(cfg, n_envs=3)
    m.reset(np.random.RandomState(0))
    a_max = cfg.network.aoi_max
    m.network.aoi[:] = np.array([[1, 5, a_max - 2, a_max, 3, 9, 30]] * 3)
    m.state.slot[:] = [0, 40, 54]
    expected = []
    for e in range(3):
        ages = m.network.aoi[e].copy()
        total = 0.0
        for _ in range(cfg.scenario.horizon_slots - m.state.slot[e]):
            ages = np.minimum(ages + 1, a_max)
            total += ages.mean()
        expected.append(total)
    booked = [unserved_aoi_sum(m.params, m.state.slot[e], m.network.aoi[e]) for e in range(3)]
    np.testing.assert_allclose(booked, expected)


def test_physics_batch_places_each_envs_own_layout_and_current(cfg):
    phys = dataclasses.replace(cfg.physics, current_jitter_mps=0.2)
    venv = PhysicsVecEnv(2, n_nodes=9, layout="random", config=cfg.replace(physics=phys), seed=3)
    venv.reset()
    m = venv.mission
    assert not np.array_equal(m.network.nodes_m[0], m.network.nodes_m[1])
    for e, p in enumerate(venv.physics):
        np.testing.assert_array_equal(p.model.ptr.body_pos[p._nodes, :2], m.network.nodes_m[e])
        np.testing.assert_array_equal(p.model.ptr.opt.wind[:2], m.state.current_mps[e])
        np.testing.assert_allclose(p.positions_m(), m.state.positions_m[e])
    assert not np.array_equal(m.state.current_mps[0], m.state.current_mps[1])
    venv.close()


def test_threads_are_capped_by_the_cpus_this_process_may_use(cfg):
    too_many = usable_cpus() + 1
    accepted = rf"nthread={too_many} is invalid: accepted an integer from 0 to {usable_cpus()}"
    for make in (
        lambda: PhysicsVecEnv(2, config=cfg, nthread=too_many),
        lambda: MultiAUVVectorEnv(2, backend="mujoco", config=cfg, nthread=too_many),
        lambda: ScenarioVecEnv([(7, cfg)], 1, "mujoco", nthread=too_many),
    ):
        with pytest.raises(ValueError, match=accepted):
            make()
    venv = PhysicsVecEnv(2, config=cfg, nthread=usable_cpus())  # the most is still accepted
    venv.close()


def test_a_closed_vec_env_refuses_to_step_or_reset(cfg):
    for venv in (
        PhysicsVecEnv(2, config=cfg),
        KinematicVecEnv(2, config=cfg),
        ScenarioVecEnv([(7, cfg)], 2, "mujoco"),
        MultiAUVVectorEnv(2, backend="mujoco", config=cfg),
    ):
        venv.reset()
        actions = np.zeros((2, *venv.action_space.shape[-1:]), dtype=np.int64)
        venv.close()
        venv.close()  # closing twice is harmless
        with pytest.raises(RuntimeError, match="is closed: make a new one"):
            venv.step(actions)
        with pytest.raises(RuntimeError, match="is closed"):
            venv.reset()
