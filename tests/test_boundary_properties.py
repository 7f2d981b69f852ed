"""Property-based tests of what crosses into the compiled core: any action, and any value a
caller writes into the state the rules read, gives a correct step or a clear error, with no
write outside the arrays (guard buffers) and no non-finite output."""

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from test_native import GuardedAllocator

import iout_mj
from iout_mj import native
from iout_mj.backends.kinematic import move
from iout_mj.envs import ENV_ID, KinematicVecEnv
from iout_mj.errors import IoutError
from iout_mj.mission import Mission
from iout_mj.scenarios import make_config

N, K = 2, 7
HIGH = np.array([11, 7, K, K] * N)
SETTINGS = settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)

integers = st.integers(min_value=-(2**63), max_value=2**63 - 1)
valid = st.lists(st.integers(0, 6), min_size=4 * N, max_size=4 * N).map(
    lambda v: np.minimum(np.array(v), HIGH - 1)
)
actions = st.one_of(
    valid,
    hnp.arrays(np.int64, st.integers(0, 12), elements=integers),
    hnp.arrays(np.float64, 4 * N, elements=st.floats(allow_nan=True, allow_infinity=True)),
    hnp.arrays(np.int64, (2, 4 * N), elements=st.integers(-3, 12)),
    st.lists(st.integers(-(2**70), 2**70), max_size=10),
    st.text(max_size=5),
    st.none(),
)


@pytest.fixture(scope="module")
def env():
    env = gym.make(ENV_ID, backend="kinematic", n_auvs=N, n_nodes=K)
    env.reset(seed=0)
    return env


@SETTINGS
@given(action=actions)
def test_any_action_steps_correctly_or_is_refused_clearly(env, action):
    before = env.unwrapped.mission.state.positions_m.copy()
    slot = int(env.unwrapped.mission.state.slot)
    try:
        obs, reward, terminated, truncated, _ = env.step(action)
    except IoutError as exc:  # ActionError and the like: what is wrong and what is accepted
        assert "accepted" in str(exc)
        np.testing.assert_array_equal(env.unwrapped.mission.state.positions_m, before)
        assert int(env.unwrapped.mission.state.slot) == slot
        return
    assert np.isfinite(reward) and np.isfinite(obs).all()
    assert env.observation_space.contains(obs)
    if terminated or truncated:
        env.reset(seed=1)


@SETTINGS
@given(action=actions)
def test_any_batched_action_steps_correctly_or_is_refused_clearly(action):
    venv = KinematicVecEnv(2, n_auvs=N, n_nodes=K, seed=0)
    venv.reset()
    try:
        obs, rewards, _, _ = venv.step(action)
    except IoutError as exc:
        assert "accepted" in str(exc)
        return
    assert np.isfinite(rewards).all() and np.isfinite(obs).all()


@SETTINGS
@given(per_agent=st.lists(actions, min_size=N, max_size=N))
def test_any_per_agent_action_is_checked_on_its_own(per_agent):
    marl = iout_mj.parallel_env(n_auvs=N, n_nodes=K)
    marl.reset(seed=0)
    try:
        marl.step(dict(zip(marl.agents, per_agent, strict=True)))
    except (IoutError, ValueError) as exc:
        assert "accepted" in str(exc)


state_writes = st.lists(
    st.tuples(
        st.sampled_from(["slot", "action", "docked", "collisions"]),
        integers,
        st.integers(0, 7),
    ),
    min_size=1,
    max_size=4,
)


@SETTINGS
@given(writes=state_writes, slots=st.integers(1, 60))
def test_any_value_written_into_the_state_stays_inside_the_arrays(monkeypatch, writes, slots):
    guarded = GuardedAllocator()
    monkeypatch.setattr(native, "allocate", guarded)
    m = Mission(make_config(N, K), n_envs=2)
    m.reset(np.random.RandomState(0))
    for name, value, index in writes:
        array = getattr(m.state, name)
        array.reshape(-1)[index % array.size] = value
    action = np.tile([5, 3, 0, 1] * N, (2, 1))
    for _ in range(slots):
        try:
            move(m, action)
            m.observe()
        except native.NativeError as exc:
            assert "accepted" in str(exc) or "outside" in str(exc)
            break
    assert guarded.intact()
