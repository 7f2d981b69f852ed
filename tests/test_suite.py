"""Invariants over every registered scenario and backend (as dm_control's `suite_test.py`)."""

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

from iout_mj.config import Config
from iout_mj.envs import ENV_ID
from iout_mj.mission import OBSERVATION_LAYOUT, observation_sizes
from iout_mj.scenarios import SCENARIOS
from iout_mj.world import acoustics

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


def expected_terms(cfg, before, m, action, ending):
    """Every reward term of a slot, from the state before and after it (numpy and the Python
    link budget, not the compiled rules)."""
    rw, w, sc = cfg.reward, cfg.reward.weights, cfg.scenario
    s, net, n = m.state, m.network, m.n_auvs
    start, end = before["positions_m"], s.positions_m
    active = ~before["docked"]
    dock = np.asarray(sc.dock_center_m)
    d0, d1 = np.hypot(*(start - dock).T), np.hypot(*(end - dock).T)

    def slack(dist, docked, slot):
        reach = rw.deadline_speed_mps * (sc.horizon_slots - slot) * sc.slot_s
        return np.where(docked, 0.0, np.maximum(0.0, dist - reach))

    step = s.speed_sp * sc.slot_s  # the straight move of the slot's setpoints
    straight = start + step[:, None] * np.stack([np.cos(s.heading_sp), np.sin(s.heading_sp)], 1)
    outside = np.any((straight < 0) | (straight > np.asarray(sc.area_m)), axis=1)
    data = np.asarray(action).reshape(n, 4)[:, 3]
    stored = before["energy_j"][data]
    req = acoustics.uplink_energy_j(np.hypot(*(end - net.nodes_m[data]).T), cfg.acoustics)
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n) if not (s.docked[i] and s.docked[j])]
    gaps = [max(0.0, rw.safety_distance_m - np.hypot(*(end[i] - end[j]))) for i, j in pairs]
    served = net.deliveries.astype(float)
    jain = served.sum() ** 2 / (len(served) * (served**2).sum()) if served.any() else 0.0
    left = max(sc.horizon_slots - int(s.slot), 0)
    ages = np.minimum(net.aoi[:, None] + np.arange(1, left + 1), cfg.network.aoi_max)
    return {
        "docking_progress": w.docking_progress * np.sum(d0 - d1),
        "aoi": w.aoi * net.aoi.mean(),
        "fairness": w.fairness * (1 - jain) if served.sum() > rw.fairness_min_deliveries else 0,
        "boundary": w.boundary * np.sum(active & outside),
        "stall": w.stall * np.sum(active & (np.hypot(*(end - start).T) < rw.stall_distance_m)),
        "energy_margin": w.energy_margin
        / n
        * np.sum(np.tanh((stored - req) / (req + rw.margin_epsilon_j))[active]),
        "infeasible_uplink": w.infeasible_uplink * np.sum(active & (stored < req)),
        "collision": w.collision
        * sum(1 - np.exp(-(g**2) / (2 * rw.collision_sigma_m**2)) for g in gaps),
        "docking": w.dock_first_entry * np.sum(s.docked & active)
        + w.dock_all * (s.docked.all() and not before["docked"].all()),
        "deadline": w.deadline
        * np.sum(slack(d0, before["docked"], before["slot"]) - slack(d1, s.docked, int(s.slot))),
        "undocked_at_end": w.undocked_at_end * (n - s.docked.sum()) if ending else 0.0,
        "aoi_after_mission": w.aoi * ages.sum(axis=1).mean() if ending else 0.0,
    }


NEAR_DOCK = Config().replace(  # both AUVs 75 m from the dock centre, heading into it
    scenario=dataclasses.replace(
        Config().scenario,
        starts_m=((755.0, 830.0), (830.0, 755.0)),
        start_heading_rad=float(np.pi / 4),
        start_jitter_m=0.0,
        start_heading_jitter_deg=0.0,
    )
)


@pytest.mark.parametrize("start", ["far", "near-dock"])
@pytest.mark.parametrize(("name", "backend"), CASES)
def test_every_reward_term_follows_from_the_state(name, backend, start):
    """Each term, and the reward, against a numpy computation from the state before and
    after every slot of an episode: to T_max from the usual starts, or docking early from
    starts near the dock (the docking bonuses and the AoI after the mission)."""
    kwargs = SCENARIOS[name].env_kwargs(2)
    env = gym.make(ENV_ID, backend=backend, config=NEAR_DOCK if start != "far" else None, **kwargs)
    m = env.unwrapped.mission
    env.reset(seed=2)
    rng = np.random.default_rng(2)
    done = False
    while not done:
        s, net = m.state, m.network
        before = {
            "positions_m": s.positions_m.copy(),
            "docked": s.docked.copy(),
            "slot": int(s.slot),
            "energy_j": net.energy_j.copy(),
        }
        action = rng.integers(0, env.action_space.nvec)
        _, reward, term, trunc, info = env.step(action)
        done = term or trunc
        expected = expected_terms(m.cfg, before, m, action, done)
        assert info["reward_terms"] == pytest.approx(expected, rel=1e-9, abs=1e-9)
        assert reward == pytest.approx(sum(expected.values()), rel=1e-9, abs=1e-9)
    if start == "far":
        assert trunc and int(m.state.slot) == 55
    else:
        assert term and m.state.docked.all() and info["reward_terms"]["aoi_after_mission"] < 0
