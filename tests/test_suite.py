"""Invariants over every registered scenario and backend (as dm_control's `suite_test.py`)."""

import gymnasium as gym
import numpy as np
import pytest

from iout_mj.envs import ENV_ID
from iout_mj.mission import OBSERVATION_LAYOUT, observation_sizes
from iout_mj.scenarios import SCENARIOS

CASES = [(name, "kinematic") for name in SCENARIOS] + [
    ("paper-k7", "mujoco"),
    ("random-k5", "mujoco"),
]


def make(name, backend, n_auvs=2):
    return gym.make(ENV_ID, backend=backend, **SCENARIOS[name].env_kwargs(n_auvs))


def episode(env, seed, steps=12):
    rng = np.random.default_rng(seed)
    obs, _ = env.reset(seed=seed)
    out = [(obs, 0.0, {})]
    for _ in range(steps):
        obs, r, term, trunc, info = env.step(rng.integers(0, env.action_space.nvec))
        out.append((obs, r, info))
        if term or trunc:
            break
    return out


@pytest.mark.parametrize(("name", "backend"), CASES)
def test_observation_follows_its_one_declaration(name, backend):
    env = make(name, backend)
    obs, _ = env.reset(seed=0)
    mission = env.unwrapped.mission
    groups = mission.observation()
    assert tuple(groups) == tuple(g.name for g in OBSERVATION_LAYOUT)
    sizes = observation_sizes(mission.n_auvs, mission.n_nodes)
    assert {k: v.shape[-1] for k, v in groups.items()} == sizes
    start = 0
    for key, value in groups.items():  # the flat observation is the groups in order
        np.testing.assert_array_equal(obs[start : start + sizes[key]], value.astype(np.float32))
        start += sizes[key]
    assert start == obs.size == env.observation_space.shape[0]


@pytest.mark.parametrize(("name", "backend"), CASES)
def test_every_observation_group_holds_what_its_declaration_says(name, backend):
    env = make(name, backend)
    obs = episode(env, 2, steps=6)[-1][0]  # the compiled observation after a few slots
    m = env.unwrapped.mission
    s, net, cfg = m.state, m.network, m.cfg
    expected = {
        "auv_position": s.positions_m / np.asarray(cfg.scenario.area_m),
        "auv_heading": np.stack([np.cos(s.headings_rad), np.sin(s.headings_rad)], -1),
        "auv_speed": s.speeds_mps / cfg.motion.v_max_mps,
        "docked": s.docked.astype(float),
        "aoi": net.aoi / cfg.network.aoi_max,
        "node_energy": np.minimum(np.log10(1 + net.energy_j / 1e-3) / 5, 2.0),
        "distance": np.hypot(*np.moveaxis(s.positions_m[:, None] - net.nodes_m[None], -1, 0)),
        "dock_distance": np.hypot(*(s.positions_m - cfg.scenario.dock_center_m).T),
        "time_remaining": np.array([1 - s.slot / cfg.scenario.horizon_slots]),
    }
    diagonal = np.hypot(*cfg.scenario.area_m)
    expected["distance"] /= diagonal
    expected["dock_distance"] /= diagonal
    flat = np.concatenate([v.reshape(-1) for v in expected.values()])
    assert tuple(expected) == tuple(g.name for g in OBSERVATION_LAYOUT)
    np.testing.assert_allclose(obs, flat.astype(np.float32), rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize(("name", "backend"), CASES)
def test_no_memory_shared_between_observations(name, backend):
    env = make(name, backend)
    steps = episode(env, 1, steps=3)
    observations = [s[0] for s in steps]
    for i, a in enumerate(observations):
        for b in observations[i + 1 :]:
            assert not np.shares_memory(a, b)
    kept = observations[-1].copy()
    observations[-1][:] = 123.0  # a user writing into a returned observation changes nothing
    np.testing.assert_array_equal(env.unwrapped.mission.flat_observation(), kept)


@pytest.mark.parametrize(("name", "backend"), CASES)
def test_same_seed_same_trajectory(name, backend):
    env = make(name, backend)
    a, b = episode(env, 4), episode(env, 4)
    for (oa, ra, ia), (ob, rb, ib) in zip(a, b, strict=True):
        np.testing.assert_array_equal(oa, ob)
        assert ra == rb and ia.get("reward_terms") == ib.get("reward_terms")
    c = episode(env, 5)
    assert not np.array_equal(a[0][0], c[0][0])


@pytest.mark.parametrize(("name", "backend"), CASES)
def test_reward_is_the_sum_of_its_terms(name, backend):
    env = make(name, backend)
    for _obs, reward, info in episode(env, 2)[1:]:
        assert reward == sum(info["reward_terms"].values())
        assert all(np.isfinite(v) for v in info["reward_terms"].values())
