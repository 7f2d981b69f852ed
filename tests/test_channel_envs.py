"""The channel's `info["channel"]` in every env flavour: the SB3 vector envs, gymnasium's vector
env and the PettingZoo parallel env carry, for each environment, what the gymnasium env carries
for the same seed, step for step."""

import dataclasses

import gymnasium as gym
import numpy as np
from conftest import ROOT

import iout_mj
from iout_mj.config import Config
from iout_mj.envs import ENV_ID, KinematicVecEnv, PhysicsVecEnv
from iout_mj.envs.gym_vector import MultiAUVVectorEnv
from iout_mj.scenarios import load_config, make_config

REALISTIC = ROOT / "training/configs/env/realistic-channel.yaml"
QUANTITIES = ("sinr_db", "per", "packets_sent", "packets_received")


def realistic(n_auvs: int = 2, n_nodes: int = 7) -> Config:
    """The shipped realistic channel (depth, propagation, packets, interference, fading)."""
    return make_config(n_auvs, n_nodes, base=load_config(REALISTIC))


def assert_same_channel(got: dict, expected: dict) -> None:
    """`got` is the single env's `info["channel"]` (NaN where no transmission reached an AUV)."""
    assert set(got) == set(QUANTITIES)
    for name in QUANTITIES:
        np.testing.assert_array_equal(np.asarray(got[name]), np.asarray(expected[name]), name)


def test_every_env_flavour_carries_the_single_envs_channel_for_the_same_seed(rng):
    """A batch of one draws from its one RNG what a single env seeded alike draws, so its
    channel entry is the single env's, through episode ends and autoresets."""
    cfg = realistic()
    single = gym.make(ENV_ID, backend="kinematic", config=cfg)
    sb3 = KinematicVecEnv(1, config=cfg, seed=0)
    vector = MultiAUVVectorEnv(1, backend="kinematic", config=cfg)
    parallel = iout_mj.parallel_env(config=cfg)
    single.reset(seed=0)
    sb3.reset()
    vector.reset(seed=0)
    parallel.reset(seed=0)
    sent = received = ends = nan_links = 0
    for _ in range(120):
        action = rng.integers(0, single.action_space.nvec)
        _, _, term, trunc, info = single.step(action)
        _, _, _, sb3_infos = sb3.step(action[None])
        _, _, _, _, vector_info = vector.step(action[None])
        _, _, _, _, parallel_infos = parallel.step({"auv_0": action[:4], "auv_1": action[4:]})
        expected = info["channel"]
        assert isinstance(expected["sinr_db"], list)
        assert_same_channel(sb3_infos[0]["channel"], expected)
        assert_same_channel({k: v[0] for k, v in vector_info["channel"].items()}, expected)
        assert vector_info["_channel"].tolist() == [True]
        for agent in parallel.possible_agents:
            assert_same_channel(parallel_infos[agent]["channel"], expected)
        sent += sum(expected["packets_sent"])
        received += sum(expected["packets_received"])
        nan_links += int(np.isnan(expected["sinr_db"]).sum())
        if term or trunc:
            ends += 1
            assert "metrics" in sb3_infos[0] and "channel" in sb3_infos[0]
            single.reset()
            parallel.reset()
    assert ends >= 2 and 0 < received < sent and nan_links > 0


def test_each_env_of_a_batch_carries_its_own_links():
    """Three environments flying different actions on a channel that draws nothing (depth,
    propagation, interference): env e's entry is that of a single env flying env e's actions
    (the (B, N) arrays are not transposed or shared between envs)."""
    base = realistic()
    scenario = dataclasses.replace(base.scenario, start_jitter_m=0.0, start_heading_jitter_deg=0.0)
    channel = dataclasses.replace(base.channel, features=("depth", "propagation", "interference"))
    cfg = base.replace(scenario=scenario, channel=channel)
    batch = KinematicVecEnv(3, config=cfg, seed=0)
    singles = [gym.make(ENV_ID, backend="kinematic", config=cfg) for _ in range(3)]
    batch.reset()
    for e, env in enumerate(singles):
        env.reset(seed=e)
    actions_rng = np.random.default_rng(1)
    differ = 0
    for _ in range(70):
        actions = actions_rng.integers(0, batch.action_space.nvec, size=(3, 8))
        _, _, dones, infos = batch.step(actions)
        rows = []
        for e, env in enumerate(singles):
            *_, term, trunc, info = env.step(actions[e])
            assert_same_channel(infos[e]["channel"], info["channel"])
            rows.append(info["channel"]["sinr_db"])
            if term or trunc:
                assert dones[e]
                env.reset()
        differ += not np.array_equal(rows[0], rows[1], equal_nan=True)
    assert differ > 10


def test_no_channel_entry_on_the_papers_channel(cfg):
    sb3 = KinematicVecEnv(2, config=cfg, seed=0)
    vector = MultiAUVVectorEnv(2, backend="kinematic", config=cfg)
    sb3.reset()
    vector.reset(seed=0)
    actions = np.zeros((2, 8), dtype=int)
    assert sb3.step(actions)[3] == [{}, {}]
    assert "channel" not in vector.step(actions)[4]


def test_the_physics_batch_carries_the_single_envs_channel():
    """MuJoCo: a batch of one (one `mujoco.rollout` call per slot) and the dm_control env."""
    cfg = realistic()
    single = gym.make(ENV_ID, backend="mujoco", config=cfg)
    batch = PhysicsVecEnv(1, config=cfg, nthread=1, seed=0)
    single.reset(seed=0)
    batch.reset()
    rng = np.random.default_rng(2)
    received = 0
    for _ in range(15):
        action = rng.integers(0, single.action_space.nvec)
        *_, info = single.step(action)
        got = batch.step(action[None])[3][0]["channel"]
        expected = info["channel"]
        np.testing.assert_allclose(got["sinr_db"], expected["sinr_db"], rtol=1e-9)
        np.testing.assert_allclose(got["per"], expected["per"], rtol=1e-9, atol=1e-300)
        assert got["packets_sent"] == expected["packets_sent"]
        assert got["packets_received"] == expected["packets_received"]
        received += sum(expected["packets_received"])
    batch.close()
    assert received > 0
