"""gymnasium's vector API over the batched core: make_vec, same-step autoreset, and a batch
that equals independent envs step for step."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space
from test_vec_env import docked_start

from iout_mj.envs import ENV_ID
from iout_mj.envs.gym_vector import MultiAUVVectorEnv
from iout_mj.mission import ActionError, observation_sizes


def make_vec(num_envs, **kw):
    return gym.make_vec(ENV_ID, num_envs=num_envs, vectorization_mode="vector_entry_point", **kw)


def test_make_vec_gives_the_batched_env_with_batched_spaces():
    envs = make_vec(5, backend="kinematic", n_auvs=2, n_nodes=13)
    assert isinstance(envs, MultiAUVVectorEnv)
    single = gym.make(ENV_ID, backend="kinematic", n_auvs=2, n_nodes=13)
    assert envs.single_observation_space == single.observation_space
    assert envs.single_action_space == single.action_space
    assert envs.observation_space == batch_space(single.observation_space, 5)
    assert envs.action_space == batch_space(single.action_space, 5)
    assert envs.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    obs, info = envs.reset(seed=0)
    assert envs.observation_space.contains(obs) and info == {}
    obs, rewards, term, trunc, info = envs.step(envs.action_space.sample())
    assert obs.shape == (5, sum(observation_sizes(2, 13).values())) and rewards.shape == (5,)
    assert term.dtype == bool and trunc.dtype == bool
    assert set(info["reward_terms"]) == set(single.unwrapped.reward_terms)
    np.testing.assert_allclose(sum(info["reward_terms"].values()), rewards)
    envs.close()


@pytest.mark.parametrize(("backend", "steps"), [("kinematic", 120), ("mujoco", 60)])
def test_batch_equals_independent_envs_with_same_step_autoreset(cfg, rng, backend, steps):
    cfg = docked_start(cfg)
    envs = make_vec(3, backend=backend, config=cfg)
    singles = [gym.make(ENV_ID, backend=backend, config=cfg) for _ in range(3)]
    obs, _ = envs.reset(seed=0)
    for e, env in enumerate(singles):
        np.testing.assert_array_equal(obs[e], env.reset(seed=e)[0])
    ends = np.zeros(3, dtype=int)
    for _ in range(steps):
        actions = rng.integers(0, envs.single_action_space.nvec, size=(3, 8))
        actions[0, 0::4], actions[0, 1::4] = 5, 6  # env 0 docks after one slot
        obs, rewards, term, trunc, info = envs.step(actions)
        for e, env in enumerate(singles):
            o, r, t, tr, i = env.step(actions[e])
            assert rewards[e] == pytest.approx(r, rel=1e-6, abs=1e-6)
            assert (term[e], trunc[e]) == (t, tr)
            for k, v in i["reward_terms"].items():
                assert info["reward_terms"][k][e] == pytest.approx(v, abs=1e-9)
            if t or tr:
                ends[e] += 1
                assert info["_final_obs"][e]
                np.testing.assert_allclose(info["final_obs"][e], o, atol=1e-6)
                assert (
                    info["final_info"]["metrics"]["mission_slots"][e]
                    == i["metrics"]["mission_slots"]
                )
                o, _ = env.reset()
            np.testing.assert_allclose(obs[e], o, atol=1e-6)
    assert ends[0] == steps and ends[1:].min() > 0
    envs.close()


def test_vector_env_errors_are_clear(cfg):
    envs = make_vec(2, backend="kinematic", config=cfg)
    with pytest.raises(RuntimeError, match="call reset"):
        envs.step(np.zeros((2, 8), dtype=int))
    with pytest.raises(ValueError, match="one integer for the whole batch"):
        envs.reset(seed=[0, 1])
    envs.reset(seed=1)
    bad = np.zeros((2, 8), dtype=int)
    bad[1, 2] = 9
    with pytest.raises(ActionError, match=r"env 1, AUV 0: aet_node index 9"):
        envs.step(bad)
