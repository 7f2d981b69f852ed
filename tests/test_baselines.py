"""Baselines and the evaluation harness."""

import dataclasses
import hashlib
import json

import gymnasium as gym
import numpy as np
import pytest

from iout_mj.agents.baselines import steer
from iout_mj.agents.planners import schedule_uplinks
from iout_mj.agents.policies import load_policy
from iout_mj.agents.registry import POLICIES, make_policy
from iout_mj.agents.rollout import run_episode
from iout_mj.config import Config
from iout_mj.envs import ENV_ID
from iout_mj.experiments.evaluate import evaluate
from iout_mj.mission import Mission
from iout_mj.mission.stats import SUMMARY_KEYS
from iout_mj.scenarios import fixed_config as scenario_config


@pytest.mark.parametrize("name", sorted(POLICIES))
@pytest.mark.parametrize(("n", "k"), [(1, 3), (2, 7), (3, 13), (4, 30)])
def test_only_valid_actions(name, n, k):
    env = gym.make(ENV_ID, backend="kinematic", config=scenario_config(n, k))
    policy = make_policy(name, seed=1)
    env.reset(seed=1)
    done = False
    while not done:
        a = policy(env.unwrapped.mission)
        assert env.action_space.contains(a)
        _, _, term, trunc, _ = env.step(a)
        done = term or trunc


@pytest.mark.parametrize("backend", ["kinematic", "mujoco"])
@pytest.mark.parametrize("name", ["greedy", "planner"])
@pytest.mark.parametrize(("n", "k"), [(1, 7), (2, 7), (2, 13)])
def test_greedy_and_planner_dock_in_time(backend, name, n, k):
    env = gym.make(ENV_ID, backend=backend, config=scenario_config(n, k))
    for seed in range(2):
        metrics = run_episode(env, load_policy(name, env, seed), seed)
        assert all(metrics["docked"]), (seed, metrics)
        assert metrics["mission_slots"] <= 55


def quick_evaluation(policies, n_auvs):
    """Three kinematic episodes per policy and N on the paper's 7 nodes, in this process."""
    rows, _ = evaluate(
        policies, n_auvs, [7], episodes=3, seed=0, backend="kinematic", workers=1, progress=False
    )
    return rows


def test_planner_beats_random_walk_on_aoi():
    rows = quick_evaluation(["planner", "random-walk"], [1, 2])
    aoi = {(r["policy"], r["n_auvs"]): r["mean_aoi"] for r in rows}
    for n in (1, 2):
        assert aoi[("planner", n)] < 0.8 * aoi[("random-walk", n)]


def test_evaluate_json_has_every_key_and_figures(tmp_path, cli):
    out = cli(
        *("evaluate", "--policy", "greedy", "planner", "--n-auvs", "1", "2", "--nodes", "5", "7"),
        *("--episodes", "2", "--backend", "kinematic", "--json", "--out", tmp_path),
    )
    rows = json.loads(out.stdout)
    assert len(rows) == 2 * 2 * 2
    keys = {"policy", "n_auvs", "n_nodes", "backend", "episodes"}
    keys |= set(SUMMARY_KEYS) | {k + "_std" for k in SUMMARY_KEYS}
    for r in rows:
        assert keys <= set(r)
        assert r["episodes"] == 2
    assert (tmp_path / "results.csv").read_text().startswith("policy,n_auvs,n_nodes")
    out = cli("figures", "--results", tmp_path)
    pngs = out.stdout.split()
    assert len(pngs) == 5
    for p in pngs:
        with open(p, "rb") as f:
            data = f.read()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000


def test_same_seed_same_start_for_every_policy():
    paths = []
    for name in ("greedy", "planner"):
        env = gym.make(ENV_ID, backend="kinematic", n_auvs=2)
        run_episode(env, load_policy(name, env, 5), seed=5)
        paths.append(np.array(env.unwrapped.mission.trace()["positions_m"]))
    assert np.array_equal(paths[0][0], paths[1][0])  # the same start state ...
    assert not np.array_equal(paths[0][1], paths[1][1])  # ... flown differently


def test_bad_policy_names_and_files(tmp_path, cli):
    env = gym.make(ENV_ID, backend="kinematic")
    with pytest.raises(ValueError, match="unknown policy 'best'"):
        load_policy("best", env)
    bad = tmp_path / "policy"
    bad.mkdir()
    (bad / "policy.json").write_text("not json")
    with pytest.raises(ValueError, match=r"cannot load policy .*policy.json.sha256 is missing"):
        load_policy(str(bad), env)
    digest = hashlib.sha256(b"not json").hexdigest()
    (bad / "policy.json.sha256").write_text(f"{digest}  policy.json\n")  # sealed, still not JSON
    with pytest.raises(ValueError, match=r"cannot load policy .*not valid JSON"):
        load_policy(str(bad), env)
    with pytest.raises(ValueError, match="holds no policy"):
        load_policy(str(tmp_path), env)
    out = cli("evaluate", "--policy", "nope", "--episodes", "1", check=False)
    assert out.returncode == 2 and "unknown policy 'nope'" in out.stderr


def test_uplink_schedule_is_near_optimal_where_every_node_can_deliver():
    """One AUV parked mid-area, nodes rich enough for any uplink: the one-step rollout
    schedule reaches 9.18 mean AoI over 55 slots (the greedy a / (K_reset - c) alone: 9.85;
    a simulated-annealing search over schedules found nothing below 9.23)."""
    cfg = scenario_config(1, 7)
    cfg = cfg.replace(network=dataclasses.replace(cfg.network, node_initial_energy_j=1000.0))
    mission = Mission(cfg)
    mission.reset(np.random.RandomState(0))
    here = np.array([[500.0, 500.0]])
    mission.state.positions_m[:] = here
    while not (mission.state.terminated or mission.state.truncated):
        node = schedule_uplinks(mission, here)
        mission.begin_slot(np.array([5, 0, 0, node[0]]))  # speed index 0: stays (v = 0)
        zero = np.zeros(1)
        mission.end_slot(here, zero, zero, zero, zero, here[None])
    metrics = mission.metrics()
    assert metrics["mission_slots"] == 55 and sum(metrics["deliveries_per_node"]) == 55
    assert metrics["mean_aoi"] == pytest.approx(9.18, abs=0.01)


def test_schedule_names_distinct_affordable_nodes():
    env = gym.make(ENV_ID, backend="kinematic", config=scenario_config(2, 13))
    env.reset(seed=0)
    mission = env.unwrapped.mission
    for _ in range(20):
        nodes = schedule_uplinks(mission, mission.state.positions_m)
        assert len(set(nodes.tolist())) == 2
        env.step(make_policy("tour-scheduler", 0)(mission))


def test_schedule_still_uplinks_where_more_auvs_than_affordable_nodes():
    """Four AUVs over the poorest of three nodes, two of which can afford an uplink: no
    assignment of distinct nodes exists, so some AUVs stay idle and the others still name both
    affordable nodes (every AUV falling back to its cheapest node would name the poor one)."""
    mission = Mission(scenario_config(4, 3))
    mission.reset(np.random.RandomState(0))
    mission.network.energy_j[:] = [1000.0, 1000.0, 0.0]
    over_poor = np.repeat(mission.network.nodes_m[2][None], 4, axis=0)
    nodes = schedule_uplinks(mission, over_poor)
    assert {0, 1} <= set(nodes.tolist())


@pytest.mark.parametrize("n", [1, 2])
def test_tour_scheduler_beats_the_planner_and_docks(n):
    rows = quick_evaluation(["planner", "tour-scheduler"], [n])
    by = {r["policy"]: r for r in rows}
    assert by["tour-scheduler"]["docking_rate"] == 1.0
    assert by["tour-scheduler"]["mean_aoi_horizon"] < by["planner"]["mean_aoi_horizon"] - 1.0


def test_random_layouts_are_the_same_for_every_policy_and_differ_by_episode(tmp_path):
    from iout_mj.experiments.evaluate import scenario_env
    from iout_mj.scenarios import resolve

    layouts = []
    for _ in range(2):  # two policies' envs, episode seeds 5 and 6
        env = scenario_env(resolve(Config(), 2, 9, "random", "kinematic"))
        layouts.append(
            [env.reset(seed=s) and env.unwrapped.mission.network.nodes_m.copy() for s in (5, 6)]
        )
    np.testing.assert_array_equal(layouts[0][0], layouts[1][0])
    assert not np.array_equal(layouts[0][0], layouts[0][1])
    rows, _ = evaluate(
        ["greedy"], [1], [9], 2, 0, "kinematic", workers=1, progress=False, layout="random"
    )
    assert rows[0]["layout"] == "random" and {"docking_rate", "mean_aoi_horizon"} <= set(rows[0])


def test_evaluate_takes_any_env_config(tmp_path, cli):
    wenz = tmp_path / "wenz.yaml"
    wenz.write_text("acoustics:\n  noise_model: wenz\n")
    args = (
        "evaluate",
        "--policy",
        "greedy",
        "--n-auvs",
        "1",
        "--episodes",
        "2",
        "--backend",
        "kinematic",
        "--json",
    )
    flat = json.loads(cli(*args).stdout)[0]
    quiet = json.loads(cli(*args, "--config", wenz).stdout)[0]
    assert quiet["delivered_bits"] > flat["delivered_bits"]  # 19 dB less noise: more uplinks
    nodes = tmp_path / "nodes.yaml"
    nodes.write_text("scenario:\n  nodes_m: [[100, 100], [900, 900]]\n")
    own = json.loads(cli(*args, "--config", nodes).stdout)[0]  # the file's nodes, every episode
    assert (own["n_nodes"], own["layout"], own["episodes"]) == (2, "custom", 2)
    bad = cli(*args, "--config", nodes, "--nodes", "7", check=False)
    assert bad.returncode == 2 and "--nodes 7 contradicts config" in bad.stderr
    assert "which sets 2 nodes" in bad.stderr


def test_the_table_stays_aligned_with_a_policy_given_by_path():
    from iout_mj.experiments.evaluate import format_table

    row = {"policy": "runs/a-very-long-run-name/best", "n_auvs": 2, "n_nodes": 7}
    row |= {"docking_rate": 1.0, "collisions": 0.0}
    for key in ("mean_aoi", "mean_aoi_horizon", "objective", "jain", "delivered_bits"):
        row |= {key: 1.0, key + "_std": 0.1}
    row |= {"propulsion_energy_j": 1.0, "propulsion_energy_j_std": 0.1}
    lines = format_table([row, {**row, "policy": "greedy"}]).splitlines()
    assert len({len(line) for line in lines}) == 1  # every row as wide as the header
    assert lines[1][len(row["policy"])] == " "  # the path does not run into N


def test_an_evaluation_in_this_process_flies_its_policies_on_one_torch_thread(monkeypatch):
    """As a worker does (`workers=1` runs here): then restores the caller's thread count."""
    import torch

    from iout_mj.experiments import evaluate as evaluation

    episode, seen = evaluation._episode, []

    def counted(job):  # the real episode, its torch threads noted
        seen.append(torch.get_num_threads())
        return episode(job)

    monkeypatch.setattr(evaluation, "_episode", counted)
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        rows = quick_evaluation(["ppo-general"], [1])
        assert seen == [1, 1, 1] and len(rows) == 1  # three episodes, one cell
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)


@pytest.mark.parametrize("along_mps", [-0.6, 0.0, 0.6])
def test_crab_steering_holds_the_track_across_a_current(along_mps):
    """East at 2 m/s toward a point 1 km away, a 0.8 m/s current from the south (plus one along
    the track): crabbing keeps the AUV within a slot's reach of its track, where the current
    alone would drift it 160 m off in 8 slots (steering at the target without crabbing: over
    100 m)."""
    offsets = {}
    for crab in (True, False):
        env = gym.make(
            ENV_ID,
            backend="kinematic",
            n_auvs=1,
            config={
                "physics": {"current_mps": [along_mps, 0.8]},
                "scenario": {"n_auvs": 1, "starts_m": [[100.0, 300.0]], "start_jitter_m": 0.0},
            },
        )
        env.reset(seed=0)
        mission = env.unwrapped.mission
        target = np.array([[1100.0, 300.0]])
        for _ in range(8):
            h, s = steer(mission, target, np.array([2.0]), crab=crab)
            env.step(np.array([h[0], s[0], 0, 0]))
        offsets[crab] = abs(mission.state.positions_m[0, 1] - 300.0)
    assert offsets[True] < 25.0 < 100.0 < offsets[False], offsets
