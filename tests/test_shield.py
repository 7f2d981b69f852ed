"""The docking shield (`agents.shield`, `P+dock`): it docks a policy that never heads home,
leaves every node choice and every action before homing to the policy, and is reachable by
name, training seeds included."""

import gymnasium as gym
import numpy as np
import pytest

from iout_mj.agents.baselines import steer
from iout_mj.agents.policies import load_policy
from iout_mj.agents.rollout import run_episode
from iout_mj.agents.shield import DockShield
from iout_mj.errors import PolicyError
from iout_mj.experiments.evaluate import learned, seed_variant


def _env(n_auvs: int = 2, n_nodes: int = 11) -> gym.Env:
    return gym.make(
        "iout_mj/MultiAUV-v0", backend="kinematic", n_auvs=n_auvs, n_nodes=n_nodes, layout="random"
    )


def test_the_shield_docks_a_policy_that_never_heads_home():
    env = _env()
    alone, shielded = [], []
    for seed in range(5):
        alone += run_episode(env, load_policy("random-walk", env, seed), seed)["docked"]
        metrics = run_episode(env, load_policy("random-walk+dock", env, seed), seed)
        shielded += metrics["docked"]
        assert np.isfinite(metrics["mean_aoi_horizon"])
    assert sum(alone) <= 2  # a random walk reaches the dock zone by chance, rarely
    assert all(shielded)


class _Recorder:
    """A base policy that remembers what it chose."""

    def __init__(self, env: gym.Env) -> None:
        self.policy = load_policy("random-walk", env, 0)
        self.chosen: list[np.ndarray] = []

    def reset(self, seed):
        self.policy.reset(seed)

    def __call__(self, env, obs):
        action = np.asarray(self.policy(env, obs))
        self.chosen.append(action.reshape(env.unwrapped.mission.n_auvs, -1).copy())
        return action


def test_the_shield_overrides_only_heading_and_speed_and_only_once_homing():
    env = _env()
    base = _Recorder(env)
    shield = DockShield(base)
    obs, _ = env.reset(seed=4)
    shield.reset(4)
    flown, done = [], False
    while not done:
        action = shield(env, obs)
        flown.append(action.reshape(2, -1))
        obs, _, terminated, truncated, _ = env.step(action)
        done = terminated or truncated
    chosen, flown = np.array(base.chosen), np.array(flown)
    assert np.array_equal(flown[:, :, 2:], chosen[:, :, 2:])  # the node choices: the policy's
    overridden = (flown[:, :, :2] != chosen[:, :, :2]).any(axis=2)
    assert overridden.any()
    for i in range(2):  # before an AUV heads home, its motion is the policy's
        first = int(np.argmax(overridden[:, i])) if overridden[:, i].any() else len(flown)
        assert np.array_equal(flown[:first, i, :2], chosen[:first, i, :2])
        assert first > 10  # a random walk is shielded near the end, not from the start


def test_a_shielded_policy_is_named_like_its_base():
    assert learned("mappo+dock") and learned("ppo-general+dock")
    assert not learned("greedy+dock")
    assert seed_variant("mappo+dock", 2, 3) == "mappo-n3-seed2+dock"
    assert seed_variant("mappo+dock", 0, 3) == "mappo+dock"
    env = _env()
    with pytest.raises(PolicyError, match="accepted"):
        load_policy("+dock", env)
    with pytest.raises(PolicyError, match="accepted"):
        load_policy("no-such-policy+dock", env)


class _StraightHome:
    """Flies at the dock at cruise speed from the first slot (and so docks early)."""

    def __call__(self, env, obs):
        m = env.unwrapped.mission
        heading, speed = steer(m, np.broadcast_to(m.dock_m, m.state.positions_m.shape), 3.0)
        zeros = np.zeros_like(heading)
        return np.stack([heading, speed, zeros, zeros], axis=1).ravel()


def test_an_auv_enters_the_dock_zone_only_once_it_heads_home():
    env = _env()
    alone = run_episode(env, _StraightHome(), 0)
    assert all(alone["docked"]) and alone["mission_slots"] < 30  # docked early, unshielded
    shield = DockShield(_StraightHome())
    obs, _ = env.reset(seed=0)
    shield.reset(0)
    mission, done = env.unwrapped.mission, False
    while not done:
        obs, _, terminated, truncated, info = env.step(shield(env, obs))
        newly = np.asarray(mission.observation()["docked"]) > 0.5
        assert not (newly & ~shield._homing).any()  # no AUV docked before heading home
        done = terminated or truncated
    assert all(info["metrics"]["docked"])
    assert info["metrics"]["mission_slots"] > alone["mission_slots"] + 15


def test_a_shielded_auvs_motion_depends_on_its_own_state_only():
    """Decentralised: moving the other AUV (anywhere, facing anywhere) changes nothing of what
    the shield does to an AUV's heading and speed, near the dock and far from it."""
    env = _env()
    env.reset(seed=5)
    mission = env.unwrapped.mission
    s = mission.state
    # heading at the dock from 150 m before it must head home (keep-out); late and far (homing)
    for slot, own_xy in ((30, (760.0, 700.0)), (50, (300.0, 300.0))):
        s.slot[...] = slot
        s.positions_m[0] = own_xy
        s.heading_sp[0], s.speed_sp[0] = 1.08, 2.5
        rows = []
        for other_xy, other_heading in (((100.0, 900.0), 0.0), ((820.0, 760.0), 2.0)):
            s.positions_m[1] = other_xy
            s.heading_sp[1] = other_heading
            s.dock_dist_m[:] = np.linalg.norm(s.positions_m - mission.dock_m, axis=1)
            shield = DockShield(lambda e, o: np.tile([5, 3, 0, 0], 2))
            rows.append(shield(env, None).reshape(2, 4)[0])
        assert np.array_equal(rows[0], rows[1])
        assert not np.array_equal(rows[0][:2], [5, 3])  # the shield acted on AUV 0
