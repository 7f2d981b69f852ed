"""The mission core driven by a fake backend (no MuJoCo): each reward term by hand."""

import dataclasses
import pickle
import subprocess
import sys

import numpy as np
import pytest

from iout_mj.config import Config
from iout_mj.mission import REWARD_TERMS, Mission
from iout_mj.scenarios import make_config
from iout_mj.world import acoustics
from iout_mj.world.geometry import wrap_angle

STRAIGHT = (5, 3)  # heading index 5: dtheta 0; speed index 3: dv 0
DOCK = np.array([830.0, 830.0])


class FakeBackend:
    """Moves every AUV straight to a given end point and books a given propulsion energy."""

    def __init__(self, mission: Mission):
        self.mission = mission

    def step(self, action, end_m, propulsion_j=0.0):
        m = self.mission
        start = m.state.positions_m.copy()
        heading, speed = m.begin_slot(np.asarray(action))
        end = np.asarray(end_m, dtype=float)
        path = np.stack([start + f * (end - start) for f in (0.5, 1.0)])
        prop = np.full(m.n_auvs, propulsion_j)
        reward = m.end_slot(end, wrap_angle(heading), speed, prop, np.zeros(m.n_auvs), path)
        return float(reward), {k: float(v) for k, v in m.terms.items()}


def mission_at(starts, n_nodes=7, heading_rad=0.0, **changes) -> Mission:
    cfg = make_config(len(starts), n_nodes)
    sc = dataclasses.replace(
        cfg.scenario,
        starts_m=tuple(starts),
        start_jitter_m=0.0,
        start_heading_jitter_deg=0.0,
        start_heading_rad=heading_rad,
        **changes,
    )
    m = Mission(cfg.replace(scenario=sc))
    m.reset(np.random.RandomState(0))
    return m


def action(*per_auv):
    return np.concatenate([[*STRAIGHT, wet, data] for wet, data in per_auv])


def test_one_slot_every_term_by_hand():
    m = mission_at([(100.0, 500.0), (400.0, 500.0)])
    ends = np.array([[125.0, 500.0], [402.0, 500.0]])  # AUV 1 moves 2 m: a stall
    reward, t = FakeBackend(m).step(action((0, 0), (1, 1)), ends, propulsion_j=1000.0)

    before = np.linalg.norm(np.array([[100.0, 500.0], [400.0, 500.0]]) - DOCK, axis=1)
    after = np.linalg.norm(ends - DOCK, axis=1)
    assert t["docking_progress"] == pytest.approx(0.02 * (before - after).sum())
    assert t["aoi"] == pytest.approx(-0.1 * 2.0)  # every node aged from 1 to 2
    assert t["fairness"] == 0.0  # no more than 3 deliveries yet
    assert t["boundary"] == 0.0
    assert t["stall"] == -1.0
    nodes = np.array([[100.0, 100.0], [800.0, 500.0]])
    req = acoustics.uplink_energy_j(np.linalg.norm(ends - nodes, axis=1), m.cfg.acoustics)
    margin = np.tanh((0.1 - req) / (req + 1e-6))  # each node stored 0.1 J
    assert t["energy_margin"] == pytest.approx(2.0 / 2 * margin.sum())
    assert t["infeasible_uplink"] == 0.0
    assert t["collision"] == 0.0  # 277 m apart, beyond d_th = 100 m
    assert t["docking"] == t["deadline"] == t["undocked_at_end"] == t["aoi_after_mission"] == 0.0
    progress = 0.02 * (before - after).sum()
    assert reward == pytest.approx(progress - 0.1 * 2.0 - 1.0 + margin.sum())  # by hand
    assert m.state.propulsion_energy_j.tolist() == [1000.0 + 40 * 25] * 2  # + hotel load


def test_boundary_attempt():
    m = mission_at([(20.0, 500.0)], heading_rad=np.pi)  # west, 1 m/s: the move ends at x = -5
    _, t = FakeBackend(m).step(action((0, 0)), [[0.0, 500.0]])
    assert t["boundary"] == -20.0


def test_collision_margin_penalty():
    m = mission_at([(300.0, 300.0), (300.0, 330.0)])
    _, t = FakeBackend(m).step(action((0, 0), (1, 1)), [[325.0, 300.0], [325.0, 330.0]])
    assert t["collision"] == pytest.approx(-4.0 * (1 - np.exp(-(70.0**2) / (2 * 20.0**2))))


def test_docking_bonuses_and_early_end():
    m = mission_at([(745.0, 830.0)])
    _, t = FakeBackend(m).step(action((0, 0)), [[770.0, 830.0]])
    assert t["docking"] == 60.0 + 10.0  # first entry, and all docked
    assert m.state.terminated and not m.state.truncated
    # ending after 1 of 55 slots: the unserved nodes keep ageing from 2 until T_max
    ages = np.minimum(2.0 + np.arange(1, 55), 50.0)
    assert t["aoi_after_mission"] == pytest.approx(-0.1 * ages.sum())
    assert t["undocked_at_end"] == 0.0


@pytest.mark.parametrize(("limit_mps", "docks"), [(None, True), (1.5, True), (0.5, False)])
def test_an_auv_docks_in_the_zone_at_or_below_the_dock_speed(limit_mps, docks):
    m = mission_at([(745.0, 830.0)], dock_max_speed_mps=limit_mps)
    FakeBackend(m).step(action((0, 0)), [[770.0, 830.0]])  # into the zone at 1 m/s
    assert m.state.speeds_mps[0] == pytest.approx(1.0)
    assert bool(m.state.docked[0]) is docks and bool(m.state.terminated) is docks


def test_fairness_once_more_than_three_deliveries():
    m = mission_at([(100.0, 500.0)])
    m.network.deliveries[:] = [4, 0, 0, 0, 0, 0, 0]
    _, t = FakeBackend(m).step(action((0, 6)), [[125.0, 500.0]])
    o = m.network.deliveries.astype(float)  # (node 6 may have delivered in the slot)
    jain = o.sum() ** 2 / (7 * (o**2).sum())
    assert t["fairness"] == pytest.approx(-2.0 * (1 - jain))


def test_deadline_shaping_and_undocked_at_the_horizon():
    m = mission_at([(100.0, 100.0)], horizon_slots=2)
    _, t = FakeBackend(m).step(action((0, 0)), [[125.0, 100.0]])
    d0, d1 = np.linalg.norm([100 - 830, 100 - 830]), np.linalg.norm([125 - 830, 100 - 830])
    slack0, slack1 = max(0.0, d0 - 2.0 * 2 * 25), max(0.0, d1 - 2.0 * 1 * 25)
    assert t["deadline"] == pytest.approx(0.1 * (slack0 - slack1))
    _, t = FakeBackend(m).step(action((0, 0)), [[150.0, 100.0]])
    assert m.state.truncated and t["undocked_at_end"] == -100.0


def test_infeasible_uplink_and_signed_weights():
    m = mission_at([(100.0, 900.0)])  # node 5 at (900, 200): far beyond what 0.1 J reaches
    _, t = FakeBackend(m).step(action((0, 5)), [[125.0, 900.0]])
    assert t["infeasible_uplink"] == -0.02
    weights = dataclasses.replace(m.cfg.reward.weights, aoi=-1.0, infeasible_uplink=-3.0)
    cfg: Config = m.cfg.replace(reward=dataclasses.replace(m.cfg.reward, weights=weights))
    m2 = Mission(cfg)
    m2.reset(np.random.RandomState(0))
    _, t2 = FakeBackend(m2).step(action((0, 5)), [[125.0, 900.0]])
    assert t2["infeasible_uplink"] == -3.0 and t2["aoi"] == pytest.approx(10 * t["aoi"])


def test_reward_terms_are_declared_once_each():
    m = mission_at([(100.0, 500.0)])
    assert len(set(REWARD_TERMS)) == len(REWARD_TERMS) == m.term_values.shape[-1] == 12


def test_batch_rows_equal_single_missions(rng):
    """A batch of 3 under the fake backend equals 3 single missions, row by row."""
    starts = [(100.0, 500.0), (400.0, 500.0)]
    single = [mission_at(starts) for _ in range(3)]
    batch = Mission(single[0].cfg, n_envs=3)
    batch.reset(np.random.RandomState(0))
    for _ in range(5):
        acts = rng.integers(0, batch.actions.high, size=(3, 8))
        ends = rng.uniform(100, 900, size=(3, 2, 2))
        start = batch.state.positions_m.copy()
        heading, speed = batch.begin_slot(acts)
        path = np.stack([start + f * (ends - start) for f in (0.5, 1.0)])
        zeros = np.zeros((3, 2))
        rewards = batch.end_slot(ends, wrap_angle(heading), speed, zeros, zeros, path)
        for e, m in enumerate(single):
            r, _ = FakeBackend(m).step(acts[e], ends[e])
            assert r == rewards[e]
            np.testing.assert_array_equal(m.flat_observation(), batch.flat_observation()[e])


def test_world_and_mission_do_not_import_mujoco():
    code = (
        "import sys, iout_mj.world.network, iout_mj.world.propulsion, iout_mj.mission, "
        "iout_mj.scenarios\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('mujoco', 'dm_control')))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_a_pickled_mission_steps_like_the_original_on_its_own_memory():
    m = mission_at([(100.0, 500.0), (400.0, 500.0)])
    copy = pickle.loads(pickle.dumps(m))  # the C view holds addresses: rebuilt on unpickling
    ends = np.array([[125.0, 500.0], [402.0, 500.0]])
    first = FakeBackend(m).step(action((0, 0), (1, 1)), ends)
    assert FakeBackend(copy).step(action((0, 0), (1, 1)), ends) == first
    np.testing.assert_array_equal(copy.flat_observation(), m.flat_observation())
    FakeBackend(copy).step(action((0, 0), (1, 1)), ends + 50.0)
    assert copy.state.slot == 2 and m.state.slot == 1
    assert not np.array_equal(copy.state.positions_m, m.state.positions_m)


def test_a_mission_with_a_non_finite_metric_is_never_reported_valid():
    from iout_mj.experiments.mission import non_finite

    metrics = {
        "return": float("nan"),
        "jain": 1.0,
        "docked": [True, False],
        "energy": [1.0, -np.inf],
    }
    assert non_finite(metrics) == ["return", "energy"]
    assert non_finite({"return": -3.5, "policy": "greedy", "docked": [True]}) == []
