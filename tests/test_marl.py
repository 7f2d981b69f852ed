"""MAPPO and IPPO through TorchRL (`training.marl`) and the team policy they export."""

import json
import subprocess
import sys
from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest
import torch
from conftest import ROOT
from pettingzoo.test import parallel_api_test

import iout_mj
from iout_mj.agents.policies import load_policy
from iout_mj.agents.rollout import run_episode
from iout_mj.agents.team_policy import (
    TeamPolicy,
    padded_observations,
    padded_state,
)
from iout_mj.cli import main
from iout_mj.envs import ENV_ID
from iout_mj.errors import CheckpointError, PolicyError, PolicyMismatchError
from iout_mj.mission.agent_view import (
    NODE_FEATURES,
    OTHER_FEATURES,
    OWN_FEATURES,
    agent_observations,
    node_present_slice,
)
from iout_mj.mission.tokens import GLOBAL_FEATURES, auv_features, node_features
from iout_mj.schema import ConfigError
from iout_mj.training import marl_imitation
from iout_mj.training.config import ImitationConfig
from iout_mj.training.marl import (
    MarlConfig,
    MarlPhase,
    TeamActions,
    TeamEnv,
    make_learner,
    restore,
    team_policy,
    train_marl,
)


def tiny(algorithm: str = "mappo", agent_steps: int = 256) -> MarlConfig:
    return MarlConfig(
        name="tiny",
        algorithm=algorithm,
        node_range=(3, 6),
        phases=(MarlPhase("kinematic", agent_steps),),
        steps_per_batch=64,
        minibatch_size=32,
        epochs=1,
        hidden=(16,),
        eval_every_batches=1,
        eval_episodes=2,
    )


def unpadded(obs: np.ndarray, n: int, k: int, n_max: int, k_max: int) -> np.ndarray:
    """A padded view (`mission.agent_view`) cut to N AUVs and K nodes."""
    head = GLOBAL_FEATURES + OWN_FEATURES
    at = head
    others = obs[at : at + OTHER_FEATURES * (n_max - 1)].reshape(n_max - 1, -1)[: n - 1]
    at += OTHER_FEATURES * (n_max - 1)
    nodes = obs[at : at + NODE_FEATURES * k_max].reshape(k_max, -1)[:k]
    at += NODE_FEATURES * k_max
    return np.concatenate([obs[:head], others.ravel(), nodes.ravel(), obs[at : at + n]])


def test_padded_views_hold_the_envs_own_and_the_tokens(rng):
    env = iout_mj.parallel_env(n_auvs=3, n_nodes=5, layout="random")
    env.reset(seed=3)
    for _ in range(4):
        env.step({a: env.action_space(a).sample() for a in env.agents})
    m = env.mission
    padded = padded_observations(m, 4, 8)
    own = agent_observations(m)
    assert own.shape == (3, env.observation_space("auv_0").shape[0])
    for i in range(3):
        np.testing.assert_array_equal(unpadded(padded[i], 3, 5, 4, 8), own[i])
    assert padded[:, node_present_slice(4, 8)].tolist() == [[1] * 5 + [0] * 3] * 3
    # against the token observation: AUV 1's own token, its links and the others' docked flags
    tokens = m.observe_tokens(k_max=5)
    a, f = auv_features(3), node_features(3)
    auv = tokens[GLOBAL_FEATURES : GLOBAL_FEATURES + 3 * a].reshape(3, a)
    node = tokens[GLOBAL_FEATURES + 3 * a : GLOBAL_FEATURES + 3 * a + 5 * f].reshape(5, f)
    view = own[1]
    np.testing.assert_array_equal(view[:GLOBAL_FEATURES], tokens[:GLOBAL_FEATURES])
    np.testing.assert_array_equal(view[GLOBAL_FEATURES : GLOBAL_FEATURES + 2], auv[1, :2])
    at = GLOBAL_FEATURES + OWN_FEATURES
    others = view[at : at + 2 * OTHER_FEATURES].reshape(2, OTHER_FEATURES)
    np.testing.assert_array_equal(others[:, :3].ravel(), auv[1, OWN_FEATURES:])
    docked = auv[:, 6]  # after position 2, heading setpoint 2, speed, speed setpoint
    assert others[:, 3].tolist() == docked[[0, 2]].tolist() and others[:, 4].tolist() == [1, 1]
    nodes = view[at + 2 * OTHER_FEATURES : at + 2 * OTHER_FEATURES + 5 * NODE_FEATURES]
    nodes = nodes.reshape(5, NODE_FEATURES)
    np.testing.assert_array_equal(nodes[:, :5], node[:, :5])  # position, AoI, progress, energy
    np.testing.assert_array_equal(nodes[:, 5:9], node[:, 5 + 4 : 5 + 8])  # AUV 1's links
    assert view[-3:].tolist() == [0, 1, 0]
    state = padded_state(m, 4, 8)
    g = {k: v.astype(np.float32) for k, v in m.observation().items()}  # state()'s groups
    auvs = state[: 4 * 8].reshape(4, 8)
    np.testing.assert_array_equal(auvs[:3, :2].ravel(), g["auv_position"])
    assert auvs[:, 7].tolist() == [1, 1, 1, 0] and not auvs[3].any()
    nodes = state[4 * 8 : -1].reshape(3 + 4, 8)
    np.testing.assert_array_equal(nodes[0, :5], g["aoi"])
    np.testing.assert_array_equal(nodes[3:6, :5].ravel(), g["distance"])
    assert nodes[2].tolist() == [1] * 5 + [0] * 3 and state[-1] == g["time_remaining"][0]
    with pytest.raises(PolicyMismatchError, match=r"accepted N <= 2 and K <= 8"):
        padded_observations(m, 2, 8)


def test_team_env_passes_the_pettingzoo_api_and_draws_k_per_episode():
    # the API test samples unmasked actions: with one K every node index is present
    parallel_api_test(TeamEnv(replace(tiny(), node_range=(5, 5)), "kinematic", 0), num_cycles=60)
    env = TeamEnv(tiny(), "kinematic", seed=0)
    ks = set()
    for seed in range(12):
        env.reset(seed=seed)
        ks.add(env.current.mission.n_nodes)
    assert ks <= {3, 4, 5, 6} and len(ks) >= 3
    env.reset(seed=0)
    k = env.current.mission.n_nodes
    with pytest.raises(ValueError, match=rf"accepted node indices from 0 to {k - 1}"):
        env.step({a: np.array([5, 3, 0, k]) for a in env.agents})


def test_a_shielded_team_env_docks_every_auv_whatever_the_actor_does():
    """Training under the shield: random joint actions fly shielded, and every AUV docks (the
    unshielded random walk docks in at most 2 of 10 AUV-episodes: tests/test_shield.py)."""
    env = TeamEnv(replace(tiny(), shield=True), "kinematic", seed=0)
    rng = np.random.default_rng(0)
    for seed in range(4):
        env.reset(seed=seed)
        mission = env.current.mission
        while env.agents:
            high = [11, 7, mission.n_nodes, mission.n_nodes]
            env.step({a: rng.integers(0, high) for a in env.agents})
        assert all(mission.metrics()["docked"]), seed


def test_the_action_mask_keeps_nodes_to_those_present():
    logits = torch.zeros(500, 2, 11 + 7 + 6 + 6)
    present = torch.tensor([1.0, 1.0, 1.0, 0.0, 0.0, 0.0]).expand(500, 2, 6)
    dist = TeamActions(logits, present, (11, 7, 6, 6))
    actions = dist.sample()
    assert actions.shape == (500, 2, 4)
    assert actions[..., 2:].max() == 2 and actions[..., 0].max() == 10
    assert torch.isfinite(dist.log_prob(actions)).all()
    np.testing.assert_allclose(dist.entropy(), np.log(11 * 7 * 3 * 3), rtol=1e-5)


@pytest.mark.parametrize("algorithm", ["mappo", "ippo"])
def test_training_saves_resumes_and_the_policy_flies_n_2_to_4(tmp_path, algorithm):
    cfg = tiny(algorithm)
    summary = train_marl(cfg, tmp_path, progress=False)
    assert summary["agent_steps"] == 256 and summary["agent_steps_per_s"] > 0
    curve = json.loads((tmp_path / "curve.json").read_text())
    assert [r["agent_steps"] for r in curve["curve"]] == [128, 256]
    assert curve["greedy"]["kinematic"]["docked_rate"] == 1.0
    best = min(curve["curve"], key=lambda r: (-r["docked_rate"], r["mean_aoi_horizon"]))
    assert curve["best"]["agent_steps"] == best["agent_steps"]
    assert (tmp_path / "best" / "policy.json").is_file()

    env = gym.make(ENV_ID, backend="kinematic", n_auvs=2, n_nodes=6, layout="random")
    env.reset(seed=0)
    obs = padded_observations(env.unwrapped.mission, 4, 6)
    learner = make_learner(cfg)
    assert restore(learner, tmp_path / "checkpoint")["agent_steps"] == 256
    assert learner.optim.state_dict()["state"]  # Adam's moments came back too
    exported = load_policy(str(tmp_path / "policy"), env)
    for mine, theirs in zip(team_policy(learner).logits(obs), exported.logits(obs), strict=True):
        torch.testing.assert_close(mine, theirs)

    with pytest.raises(CheckpointError, match="already holds a run"):
        train_marl(cfg, tmp_path, progress=False)
    with pytest.raises(CheckpointError, match="other settings"):
        train_marl(replace(cfg, hidden=(8,)), tmp_path, resume=True, progress=False)
    longer = replace(cfg, phases=(MarlPhase("kinematic", 512),))
    resumed = train_marl(longer, tmp_path, resume=True, progress=False)
    assert resumed["agent_steps"] == 512
    curve = json.loads((tmp_path / "curve.json").read_text())
    assert [r["agent_steps"] for r in curve["curve"]] == [128, 256, 384, 512]

    for n, k in ((2, 6), (3, 4), (4, 5)):
        env = gym.make(ENV_ID, backend="kinematic", n_auvs=n, n_nodes=k, layout="random")
        policy = load_policy(str(tmp_path / "policy"), env)
        assert isinstance(policy, TeamPolicy)
        metrics = run_episode(env, policy, seed=1)
        assert np.isfinite(metrics["mean_aoi_horizon"])
    big = gym.make(ENV_ID, backend="kinematic", n_auvs=2, n_nodes=7)
    with pytest.raises(PolicyMismatchError, match="K <= 6"):
        load_policy(str(tmp_path / "policy"), big)
    with pytest.raises(PolicyError, match="team policy"):
        load_policy(f"{tmp_path / 'policy'}+rollout4", env)


def test_each_auv_acts_on_its_own_observation(tmp_path):
    """Decentralised execution: an AUV's action changes only with its own observation."""
    train_marl(tiny(agent_steps=128), tmp_path, progress=False)
    env = gym.make(ENV_ID, backend="kinematic", n_auvs=2, n_nodes=5, layout="random")
    env.reset(seed=2)
    policy = load_policy(str(tmp_path / "policy"), env)
    obs = padded_observations(env.unwrapped.mission, 4, 6)
    alone = torch.stack([p.argmax(-1) for p in policy.logits(obs[:1])], -1)
    together = torch.stack([p.argmax(-1) for p in policy.logits(obs)], -1)
    assert torch.equal(alone[0], together[0])
    assert policy(env, None).shape == (8,)


def test_discounted_returns_of_the_scaled_team_reward():
    data = marl_imitation.TeamDemonstrations(rewards=[np.array([10.0, 0.0, -20.0]), np.ones(1)])
    expected = [0.1 + 0.5 * 0.0 + 0.25 * -0.2, 0.5 * -0.2, -0.2, 0.01]
    np.testing.assert_allclose(data.returns(0.5, 0.01), expected)


@pytest.mark.parametrize("algorithm", ["mappo", "ippo"])
def test_imitation_fits_each_auv_to_its_share_of_the_planners_action(algorithm):
    cfg = replace(tiny(algorithm), hidden=(64,))
    env = TeamEnv(cfg, "kinematic", seed=0)
    data = marl_imitation.TeamDemonstrations()
    rng = np.random.default_rng(0)
    metrics = marl_imitation.fly(
        env, 3, rng, None, 1.0, ImitationConfig(planner="greedy").teacher, data
    )
    assert len(metrics) == 3 and all(all(m["docked"]) for m in metrics)
    assert np.stack(data.actions).shape == (len(data.obs), 2, 4)
    assert sum(len(r) for r in data.rewards) == len(data.obs)
    torch.manual_seed(0)
    learner = make_learner(cfg)
    before, _ = marl_imitation.fit(learner, data, 0, 1e-3, rng)
    after, nll = marl_imitation.fit(learner, data, 30, 3e-3, rng)
    assert np.mean(after) > np.mean(before) + 0.2 and np.isfinite(nll)
    obs, states = torch.as_tensor(np.stack(data.obs)), torch.as_tensor(np.stack(data.states))
    with torch.no_grad():
        v = marl_imitation.values(learner, obs, states)
    targets = torch.as_tensor(data.returns(cfg.gamma, cfg.reward_scale), dtype=torch.float32)
    fitted = ((v - targets[:, None]) ** 2).mean()
    assert fitted < 0.5 * ((targets - targets.mean()) ** 2).mean()  # the critic learnt them


def test_a_teacher_with_a_docking_margin_docks_earlier():
    def docked_at(teacher):
        env = gym.make(ENV_ID, backend="kinematic", n_auvs=2, n_nodes=9, layout="random")
        env.reset(seed=5)
        policy, done = teacher(0), False
        while not done:
            _, _, terminated, truncated, info = env.step(policy(env.unwrapped.mission))
            done = terminated or truncated
        assert all(info["metrics"]["docked"])
        return env.unwrapped.mission.state.slot

    own = docked_at(ImitationConfig(planner="tour-scheduler").teacher)
    early = docked_at(ImitationConfig(planner="tour-scheduler", teacher_dock_spare_slots=8).teacher)
    assert early < own
    with pytest.raises(ConfigError, match=r"planner='greedy'.*with teacher_dock_spare_slots"):
        ImitationConfig(planner="greedy", teacher_dock_spare_slots=4)


def test_a_warm_started_run_records_its_rounds_and_resumes_without_repeating_them(tmp_path):
    im = ImitationConfig(planner="greedy", episodes=2, epochs=2, rounds=1, round_episodes=1)
    cfg = replace(tiny(agent_steps=128), imitation=im)
    train_marl(cfg, tmp_path, progress=False)
    curve = json.loads((tmp_path / "curve.json").read_text())
    rounds = curve["imitation"]["rounds"]
    assert [r["round"] for r in rounds] == [0, 1] and rounds[1]["states"] > rounds[0]["states"]
    assert [r["agent_steps"] for r in curve["curve"]] == [0, 128]
    resumed = train_marl(
        replace(cfg, phases=(MarlPhase("kinematic", 256),)), tmp_path, resume=True, progress=False
    )
    assert resumed["imitation"] == curve["imitation"] and resumed["agent_steps"] == 256


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"algorithm": "qmix"}, r"algorithm.*one of \('mappo', 'ippo'\)"),
        ({"minibatch_size": 100}, "must divide steps_per_batch"),
        ({"n_max": 1}, "n_max"),
        ({"layout": "paper"}, "random"),
        (
            {"imitation": ImitationConfig(node_range=(3, 9))},
            r"imitation.node_range: accepted null for a team policy",
        ),
    ],
)
def test_bad_configs_say_what_is_accepted(change, match):
    with pytest.raises(ConfigError, match=match):
        replace(tiny(), **change)


@pytest.mark.parametrize("name", ["mappo-n2", "mappo-n3", "mappo-n4", "ippo-n2"])
def test_shipped_configs_load(name):
    cfg = MarlConfig.load(ROOT / "training" / "configs" / f"{name}.yaml")
    assert cfg.algorithm == name.split("-")[0] and cfg.n_auvs == int(name[-1])
    assert cfg.node_range == (3, 20) and cfg.imitation is not None
    assert cfg.shield == (cfg.algorithm == "mappo")  # the MAPPO recipe trains under the shield


def test_train_marl_command(tmp_path, capsys):
    config = tmp_path / "mappo-tiny.yaml"
    config.write_text(
        "name: mappo-tiny\nnode_range: [3, 4]\nphases: [{backend: kinematic, agent_steps: 64}]\n"
        "steps_per_batch: 32\nminibatch_size: 32\nepochs: 1\nhidden: [8]\neval_episodes: 1\n"
    )
    out = tmp_path / "run"
    args = ["train-marl", str(config), "--steps", "128", "--quiet", "--out", str(out)]
    assert main(args) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["algorithm"] == "mappo" and summary["agent_steps"] == 128
    assert (out / "policy" / "policy.json").is_file()


def test_torchrl_example_runs(tmp_path):
    config = tmp_path / "mappo-tiny.yaml"
    config.write_text(
        "name: mappo-tiny\nn_max: 3\nnode_range: [3, 4]\nsteps_per_batch: 32\n"
        "minibatch_size: 32\nepochs: 1\nhidden: [8]\neval_episodes: 1\n"
    )
    script = ROOT / "training" / "examples" / "torchrl_mappo.py"
    args = ["--config", config, "--steps", "64", "--episodes", "1", "--out", tmp_path / "run"]
    subprocess.run([sys.executable, script, *args], capture_output=True, check=True)
    rows = json.loads((tmp_path / "run" / "evaluation.json").read_text())
    assert [(r["policy"] == "greedy", r["n_auvs"]) for r in rows] == [
        (True, 2),
        (False, 2),
        (True, 3),
        (False, 3),
    ]
