"""PettingZoo: one agent per AUV, the team reward, the global state for a centralised critic."""

import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from conftest import ROOT
from pettingzoo.test import parallel_api_test, parallel_seed_test

import iout_mj
from iout_mj.envs import ENV_ID
from iout_mj.envs.parallel_env import agent_observation_size


@pytest.mark.parametrize(
    ("n", "k", "backend"), [(1, 7, "kinematic"), (3, 13, "kinematic"), (2, 7, "mujoco")]
)
def test_pettingzoo_api_and_seed_tests(n, k, backend):
    parallel_api_test(iout_mj.parallel_env(n_auvs=n, n_nodes=k, backend=backend), num_cycles=60)
    parallel_seed_test(lambda: iout_mj.parallel_env(n_auvs=n, n_nodes=k, layout="random"))


def test_team_reward_state_and_own_observations_match_the_gymnasium_env(rng):
    env = iout_mj.parallel_env(n_auvs=2, n_nodes=7)
    single = gym.make(ENV_ID, backend="kinematic", n_auvs=2, n_nodes=7)
    obs, _ = env.reset(seed=4)
    flat, _ = single.reset(seed=4)
    assert env.agents == ["auv_0", "auv_1"]
    np.testing.assert_array_equal(env.state(), flat)
    assert obs["auv_0"].shape == (agent_observation_size(2, 7),)
    while env.agents:
        actions = {a: env.action_space(a).sample() for a in env.agents}
        obs, rewards, term, trunc, infos = env.step(actions)
        flat, reward, t, tr, info = single.step(
            np.concatenate([actions["auv_0"], actions["auv_1"]])
        )
        np.testing.assert_array_equal(env.state(), flat)
        assert rewards == {"auv_0": reward, "auv_1": reward}  # the team's reward
        assert infos["auv_1"]["reward_terms"] == info["reward_terms"]
        m = env.mission
        for i, agent in enumerate(("auv_0", "auv_1")):
            own = obs[agent][3:5]  # after the clock, the node share and the mean AoI
            np.testing.assert_allclose(own, m.state.positions_m[i] / 1000, atol=1e-6)
            other = m.state.positions_m[1 - i] - m.state.positions_m[i]
            bearing = np.arctan2(other[1], other[0]) - m.state.heading_sp[i]
            seen = obs[agent][3 + 11 : 3 + 11 + 3]  # the other AUV, relative to this one
            expected = [np.hypot(*other) / (1000 * np.sqrt(2)), np.cos(bearing), np.sin(bearing)]
            np.testing.assert_allclose(seen, expected, atol=1e-5)
    assert term["auv_0"] == t and trunc["auv_0"] == tr


def test_missing_actions_are_named():
    env = iout_mj.parallel_env(n_auvs=2, n_nodes=7)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"missing for \['auv_1'\]"):
        env.step({"auv_0": np.array([5, 3, 0, 0])})


@pytest.mark.slow
def test_shared_policy_example_runs(tmp_path):
    script = ROOT / "training" / "examples" / "pettingzoo_shared_ppo.py"
    out = subprocess.run(
        [sys.executable, str(script), "--steps", "1024", "--episodes", "1", "--out", tmp_path],
        capture_output=True,
        text=True,
        check=True,
    )
    assert '"mean_aoi_horizon"' in out.stdout and (tmp_path / "result.json").is_file()


@pytest.mark.parametrize(
    ("actions", "match"),
    [
        # 5 and 3 entries: together 8, the joint size, which must not shift between agents
        ({"auv_0": [5, 3, 0, 0, 1], "auv_1": [5, 3, 0]}, r"actions\['auv_0'\] has shape \(5,\)"),
        ({"auv_0": [5, 3, 0, 0], "auv_1": [5, 3, 0]}, r"actions\['auv_1'\] has shape \(3,\)"),
        ({"auv_0": [5, 3, 0, 0], "auv_1": [5, 3, 7, 0]}, r"actions\['auv_1'\] = \[5, 3, 7, 0\]"),
        ({"auv_0": [5, 3, 0, -1], "auv_1": [5, 3, 0, 0]}, r"auv_0.*accepted integers from 0"),
        ({"auv_0": [5, 3, 0.5, 0], "auv_1": [5, 3, 0, 0]}, r"auv_0.*accepted integers"),
        ({"auv_0": [5, 3, 0, 0], "auv_1": [5, 3, 0, 0], "auv_2": [0] * 4}, r"\['auv_2'\]"),
    ],
)
def test_each_agents_action_is_checked_on_its_own(actions, match):
    env = iout_mj.parallel_env(n_auvs=2, n_nodes=7)
    env.reset(seed=0)
    before = env.state().copy()
    with pytest.raises(ValueError, match=match):
        env.step(actions)
    np.testing.assert_array_equal(env.state(), before)  # nothing moved
