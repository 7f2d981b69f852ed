"""Decision-time rollout search (`agents.search`): its model is the env's own on the kinematic
backend, it never does worse than the policy it improves there, and it is reachable by name."""

import re
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from conftest import ROOT

from iout_mj.agents.policies import load_policy, read_trained, split_search
from iout_mj.agents.rollout import run_episode
from iout_mj.agents.search import (
    LATE_PENALTY,
    UNDOCKED_PENALTY,
    RolloutSearch,
    best_candidate,
    copy_state,
)
from iout_mj.envs.batch import MissionBatch
from iout_mj.errors import PolicyError


def _env(n_auvs: int = 1, n_nodes: int = 5) -> gym.Env:
    return gym.make(
        "iout_mj/MultiAUV-v0", backend="kinematic", n_auvs=n_auvs, n_nodes=n_nodes, layout="random"
    )


def _score(metrics: dict) -> float:
    undocked = len(metrics["docked"]) - sum(metrics["docked"])
    return metrics["mean_aoi_horizon"] + UNDOCKED_PENALTY * undocked


def test_a_copied_mission_flown_by_the_policy_ends_as_the_env_does():
    env = _env()
    base = read_trained("ppo-general", env)
    env.reset(seed=3)
    for _ in range(4):  # mid-mission
        env.step(base(env, None))
    batch = MissionBatch(2, "kinematic", config=env.unwrapped.env_spec.config, observation="tokens")
    copy_state(env.unwrapped.mission, batch)
    k_max = base.manifest["k_max"]
    done = False
    while not done:
        _, _, terminated, truncated, info = env.step(base(env, None))
        batch.move(base.act(batch.mission.observe_tokens(k_max)))
        done = terminated or truncated
    assert batch.mission.state.terminated.all() or batch.mission.state.truncated.all()
    keys = ("mean_aoi_horizon", "mean_aoi", "jain", "delivered_bits", "mission_slots", "docked")
    for e in range(2):
        copied = batch.mission.metrics(e)
        assert {k: copied[k] for k in keys} == {k: info["metrics"][k] for k in keys}


def test_an_auv_still_undocked_at_the_deadline_costs_the_late_penalty():
    """MuJoCo's margin: a rollout with AUVs out of the dock `deadline` slots in pays for each;
    a deadline the rollout never reaches (the kinematic backend's: the horizon) costs nothing."""
    env = _env(n_auvs=2, n_nodes=5)
    base = read_trained("ppo-general", env)
    env.reset(seed=0)
    search = RolloutSearch(base, candidates=4, seed=0)
    horizon = env.unwrapped.env_spec.config.scenario.horizon_slots
    first = search._candidate_actions(env.unwrapped.mission.observe_tokens(search.k_max))
    scores = {}
    for deadline in (horizon, horizon + 1, 1):  # nobody docks within one slot of the start
        scores[deadline] = search.rollouts(env, first, deadline)[0]
    np.testing.assert_array_equal(scores[horizon], scores[horizon + 1])
    np.testing.assert_allclose(scores[1] - scores[horizon], 2 * LATE_PENALTY)


@pytest.mark.parametrize("seed", [0, 1])
def test_the_search_never_ends_worse_than_its_policy_on_the_exact_model(seed):
    env = _env(n_auvs=2, n_nodes=5)
    base = read_trained("ppo-general", env)
    plain = run_episode(env, base, seed=seed)
    searched = run_episode(env, RolloutSearch(base, candidates=4, seed=seed), seed=seed)
    assert _score(searched) <= _score(plain) + 1e-9


def test_bits_break_only_exact_ties_of_the_score():
    bits = np.array([1.0, 3.0, 2.0, 9.0])
    assert best_candidate(np.array([5.0, 5.0, 5.0, 5.0 + 1e-6]), bits) == 1  # AoI first
    assert best_candidate(np.array([5.0, 5.0, 5.0 + 1e-15, 4.0]), bits) == 3
    assert best_candidate(np.array([2.0, 2.0, 2.0, 2.0]), np.zeros(4)) == 0  # then the first
    assert best_candidate(np.array([1002.0, 1003.0, 1002.0, 1004.0]), bits) == 2


def test_the_search_delivers_the_most_bits_among_its_tied_candidates():
    """Every slot flown is one whose rollout has the least score and, among equal scores, the
    most bits: the search's own rollouts, recomputed, agree with its choice all mission long."""
    env = _env(n_auvs=2, n_nodes=5)
    base = read_trained("ppo-general-n2-aoi-2m", env)  # whose candidates tie here (README)
    search = RolloutSearch(base, candidates=16, seed=1)
    env.reset(seed=1)
    search.reset(1)
    horizon = env.unwrapped.env_spec.config.scenario.horizon_slots
    decided_by_bits = 0
    done = False
    while not done:
        tokens = env.unwrapped.mission.observe_tokens(search.k_max)
        rng = search.rng.bit_generator.state
        actions = search._candidate_actions(tokens)
        scores, bits = search.rollouts(env, actions, horizon)
        search.rng.bit_generator.state = rng  # the search draws the same candidates
        chosen = search(env, None)
        pick = next(i for i, a in enumerate(actions) if np.array_equal(a, chosen))
        tied = scores == scores.min()
        assert tied[pick] and bits[pick] == bits[tied].max()
        decided_by_bits += int(len(set(bits[tied])) > 1)
        _, _, terminated, truncated, _ = env.step(chosen)
        done = terminated or truncated
    assert decided_by_bits > 0  # the rule was exercised (22 of 55 slots here)


def test_one_candidate_is_the_policy_itself():
    env = _env()
    base = read_trained("ppo-general", env)
    plain = run_episode(env, base, seed=2)
    assert run_episode(env, RolloutSearch(base, candidates=1), seed=2) == plain


def test_the_search_is_named_after_the_policy_it_improves():
    assert split_search("ppo-general+rollout") == ("ppo-general", 16)
    assert split_search("runs/x-seed0/best+rollout8") == ("runs/x-seed0/best", 8)
    assert split_search("ppo-general") == ("ppo-general", None)
    env = _env()
    assert isinstance(load_policy("ppo-general+rollout4", env), RolloutSearch)
    with pytest.raises(PolicyError, match="C from 1 to 1024"):
        split_search("ppo-general+rollout0")
    with pytest.raises(PolicyError, match="general"):
        load_policy("ppo-n1-k7+rollout", gym.make("iout_mj/MultiAUV-v0", n_auvs=1))


def test_candidates_are_distinct_and_start_with_the_policy_action():
    env = _env(n_auvs=2, n_nodes=7)
    base = read_trained("ppo-general", env)
    env.reset(seed=0)
    search = RolloutSearch(base, candidates=8, seed=0)
    tokens = env.unwrapped.mission.observe_tokens(search.k_max)
    actions = search._candidate_actions(tokens)
    assert len({tuple(a) for a in actions}) == len(actions) > 1
    np.testing.assert_array_equal(actions[0], base.act(tokens[None])[0])


@pytest.mark.parametrize("config", [None, "training/configs/env/current-1mps.yaml"])
def test_the_model_error_example_finds_the_rollout_model_close_to_the_physics(config):
    """Along its track the rollouts' model stays within 2 m of the hull per slot, in a 1 m/s
    current too, with it along the track, across it or against it (each bin within 4 m: the
    model that added the current to the speed through the water was 12 and 16 m off)."""
    script = ROOT / "training" / "examples" / "rollout_model_error.py"
    flags = ["--seeds", "1"] + (["--config", str(ROOT / config)] if config else [])
    out = subprocess.run(
        [sys.executable, str(script), *flags], capture_output=True, text=True, check=True
    ).stdout
    ahead = float(re.search(r"model ahead along its track by (-?[0-9.]+) m", out).group(1))
    assert re.match(r"[1-9][0-9]* AUV-slots", out) and abs(ahead) < 2.0  # 0.4 / 1.2 m, 5 seeds
    bins = [float(b) for b in re.findall(r"AUV-slots, model ahead by (-?[0-9.]+) m", out)]
    assert len(bins) == (3 if config else 1) and max(map(abs, bins)) < 4.0
