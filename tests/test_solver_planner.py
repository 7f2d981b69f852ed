"""The solver-grade baseline: PyVRP's tours, flights round the dock zone, whole missions."""

import json

import numpy as np
import pytest

from iout_mj.agents.planners import _tour_order
from iout_mj.agents.registry import make_policy
from iout_mj.agents.solver_planner import (
    _problem,
    _solve,
    dock_waypoints,
    leg_lengths_m,
    solve_tours,
)
from iout_mj.config import Config
from iout_mj.experiments.evaluate import scenario_env
from iout_mj.scenarios import random_layout, resolve

DOCK = np.array([830.0, 830.0])
CLEAR_M = 120.0
BUDGET_M = 55 * 25 * 3.0


def starts(n):
    return np.array([[50.0, 50.0 + 100 * i] for i in range(n)])


def layout(k, seed):
    return np.array(random_layout(k, seed))


def path_m(points):
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


@pytest.mark.parametrize(("n", "k"), [(1, 2), (1, 13), (2, 7), (3, 20), (4, 30)])
def test_every_node_once_over_all_auvs_and_the_same_tours_every_time(n, k):
    nodes = layout(k, k)
    tours = solve_tours(starts(n), nodes, DOCK, CLEAR_M, BUDGET_M)
    assert len(tours) == n
    assert sorted(x for t in tours for x in t) == list(range(k))
    assert solve_tours(starts(n), nodes, DOCK, CLEAR_M, BUDGET_M) == tours
    if k >= 4 * n:  # many nodes: the longest route is bisected down, every AUV takes some
        assert all(tours)


def test_every_route_runs_from_its_start_to_the_dock():
    n, nodes = 3, layout(11, 0)
    data = _problem(starts(n), nodes, DOCK, CLEAR_M, BUDGET_M)
    _, solution = _solve(data, seed=0)
    assert data.num_depots == n + 1  # the starts, then the dock
    for route in solution.routes():
        assert route.start_depot() == route.vehicle_type() < n
        assert route.end_depot() == n
    # the last leg: to the nodes' centroid in the objective, into the dock in the budget
    centre = nodes.mean(axis=0)
    for route in solution.routes():
        last = nodes[[a.idx for a in route.schedule() if a.is_client()][-1]]
        to_dock, to_centre = np.linalg.norm(last - DOCK), np.linalg.norm(last - centre)
        assert route.duration() - route.distance() == round(to_dock) - round(to_centre)


@pytest.mark.parametrize("seed", range(4))
def test_shorter_than_the_nearest_neighbour_tours(seed):
    """One AUV: the solver's path is no longer than the nearest-neighbour one; two: its longer
    route no longer than that of the tour scheduler's halves of the nearest-neighbour order."""
    nodes = layout(20, seed)
    one = starts(1)
    (tour,) = solve_tours(one, nodes, DOCK, CLEAR_M, BUDGET_M)
    nearest = _tour_order(one[0], nodes)
    assert path_m(np.concatenate([one, nodes[tour]])) <= path_m(
        np.concatenate([one, nodes[nearest]])
    )
    two = starts(2)
    tours = solve_tours(two, nodes, DOCK, CLEAR_M, BUDGET_M)
    halves = np.array_split(np.array(_tour_order(two.mean(axis=0), nodes)), 2)
    longest = max(path_m(np.concatenate([two[i : i + 1], nodes[t]])) for i, t in enumerate(tours))
    halves_m = [min(path_m(np.concatenate([s[None], nodes[h]])) for s in two) for h in halves]
    assert longest <= max(halves_m)


def test_legs_go_round_the_dock_zone():
    a = np.array([[830.0, 500.0], [500.0, 500.0]])
    b = np.array([[830.0, 990.0], [600.0, 500.0]])
    way = dock_waypoints(a, b, DOCK, CLEAR_M)
    assert np.linalg.norm(way[0] - DOCK) > CLEAR_M  # through the dock: a waypoint beside it
    for leg in ((a[0], way[0]), (way[0], b[0])):  # and neither half crosses the zone
        t = np.linspace(0, 1, 101)[:, None]
        assert np.linalg.norm(leg[0] + t * (leg[1] - leg[0]) - DOCK, axis=1).min() > 70.0
    np.testing.assert_array_equal(way[1], b[1])  # far from the dock: straight
    lengths = leg_lengths_m(np.concatenate([a[:1], b[:1]]), DOCK, CLEAR_M)
    assert lengths[0, 1] > 490.0 + 20.0  # the detour is longer than the straight 490 m


@pytest.mark.parametrize(("n", "k"), [(3, 11), (4, 20)])
def test_three_and_four_auvs_fly_a_whole_episode_and_dock(n, k):
    env = scenario_env(resolve(Config(), n, k, "random", "kinematic"))
    for seed in range(3):
        env.reset(seed=seed)
        policy, mission = make_policy("solver-tour", seed), env.unwrapped.mission
        done = False
        while not done:
            action = policy(mission)
            assert env.action_space.contains(action)
            _, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        metrics = info["metrics"]
        assert all(metrics["docked"]) and metrics["mission_slots"] <= 55, (seed, metrics)
        assert min(metrics["deliveries_per_node"]) >= 3  # every node's AoI was reset


def test_same_layout_same_flight():
    env = scenario_env(resolve(Config(), 2, 9, "random", "kinematic"))
    paths = []
    for _ in range(2):
        env.reset(seed=3)
        policy, mission = make_policy("solver-tour", 3), env.unwrapped.mission
        done = False
        while not done:
            _, _, terminated, truncated, _ = env.step(policy(mission))
            done = terminated or truncated
        paths.append(np.array(mission.trace()["positions_m"]))
    np.testing.assert_array_equal(paths[0], paths[1])


def test_evaluate_flies_it_by_name(cli):
    out = cli(
        *("evaluate", "--policy", "solver-tour", "--n-auvs", "3", "--nodes", "9"),
        *("--layout", "random", "--episodes", "2", "--backend", "kinematic", "--json"),
    )
    (row,) = json.loads(out.stdout)
    assert (row["policy"], row["n_auvs"], row["n_nodes"]) == ("solver-tour", 3, 9)
    assert row["docking_rate"] == 1.0 and row["mean_aoi_horizon"] < 10.0


def test_it_docks_on_the_mujoco_backend():
    env = scenario_env(resolve(Config(), 2, 13, "random", "mujoco"))
    env.reset(seed=0)
    policy, mission = make_policy("solver-tour", 0), env.unwrapped.mission
    done = False
    while not done:
        _, _, terminated, truncated, info = env.step(policy(mission))
        done = terminated or truncated
    assert all(info["metrics"]["docked"]) and info["metrics"]["mission_slots"] <= 55
