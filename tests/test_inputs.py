"""Every input checked once, at the edge: clear errors, never a silent wrong answer."""

import json
import time

import gymnasium as gym
import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from iout_mj.config import Config
from iout_mj.envs import ENV_ID
from iout_mj.mission import ActionError
from iout_mj.schema import ConfigError, load_mapping
from iout_mj.training import TrainConfig

FAST = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@pytest.mark.parametrize(
    "data",
    [
        {"acoustics": {"noise_level_db": float("nan")}},
        {"physics": {"current_mps": [float("nan"), 0.0]}},
        {"scenario": {"start_heading_rad": float("nan")}},
        {"motion": {"hotel_power_w": float("inf")}},
        {"network": {"aoi_max": float("inf")}},
        {"network": {"node_initial_energy_j": float("inf")}},
    ],
)
def test_nan_and_inf_are_refused(data):
    with pytest.raises(ConfigError, match="finite"):
        Config.from_dict(data)


def test_yaml_numbers_and_bad_files(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("motion:\n  battery_j: 2e6\n")
    assert Config.load(path).motion.battery_j == 2e6  # YAML 1.1 would read text
    path.write_text("motion:\n  battery_j: '2e6'\n")
    with pytest.raises(ConfigError, match="read as text: write it as a number"):
        Config.load(path)
    path.write_text("")
    with pytest.raises(ConfigError, match="is empty"):
        Config.load(path)
    with pytest.raises(ConfigError, match="is empty"):
        TrainConfig.load(path)
    path.write_bytes(b"motion:\n  v_max_mps: \xff\n")
    with pytest.raises(ConfigError, match=r"c\.yaml is not UTF-8"):
        Config.load(path)


def test_yaml_alias_bomb_is_refused_quickly(tmp_path):
    lines = ['a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
    for prev, name in zip("abcdefgh", "bcdefghi", strict=True):
        lines.append(f"{name}: &{name} [" + ",".join([f"*{prev}"] * 9) + "]")
    path = tmp_path / "bomb.yaml"
    path.write_text("\n".join(lines) + "\n")
    assert path.stat().st_size < 600
    start = time.perf_counter()
    with pytest.raises(ConfigError, match="YAML aliases") as err:
        Config.load(path)
    assert time.perf_counter() - start < 2 and len(str(err.value)) < 300


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"gamma": 2.0}, "gamma"),
        ({"n_epochs": 0}, "n_epochs"),
        ({"net_arch": [-5]}, "net_arch"),
        ({"learning_rate": -1.0}, "learning_rate"),
        ({"n_auvs": 9}, "n_auvs"),
        ({"layout": "spiral"}, "layout"),
        ({"eval_episodes": 0}, "eval_episodes"),
    ],
)
def test_training_config_is_validated_like_the_env_config(tmp_path, changes, match):
    path = tmp_path / "t.yaml"
    path.write_text(yaml.safe_dump(changes))
    with pytest.raises(ConfigError, match=match):
        TrainConfig.load(path)


def test_the_kinematic_backend_drifts_with_the_current_across_the_heading():
    """Heading about east at 1 m/s (the start's seeded jitter): a current from the north drifts
    the AUV by its part across the heading; the part along it leaves the ground speed as is
    (the speed servo holds it)."""
    moves, headings = [], []
    for current in ([0.0, 0.0], [0.0, -0.5], [0.5, 0.0]):
        env = gym.make(
            ENV_ID, backend="kinematic", n_auvs=1, config={"physics": {"current_mps": current}}
        )
        env.reset(seed=0)
        start = env.unwrapped.mission.state.positions_m[0].copy()
        env.step(np.array([5, 3, 0, 0]))
        moves.append(env.unwrapped.mission.state.positions_m[0] - start)
        headings.append(env.unwrapped.mission.state.heading_sp[0])
    h = np.array([np.cos(headings[0]), np.sin(headings[0])])
    assert headings[1] == headings[2] == headings[0] and abs(h[1]) < 0.1
    for move, current in zip(moves[1:], ([0.0, -0.5], [0.5, 0.0]), strict=True):
        across = np.asarray(current) - (h @ current) * h
        np.testing.assert_allclose(move - moves[0], across * 25, atol=1e-9)
    assert np.linalg.norm(moves[1] - moves[0]) > 12.0  # nearly all of the 0.5 m/s current


def test_step_after_the_end_and_bad_seeds():
    env = gym.make(ENV_ID, backend="kinematic", n_auvs=1, config={"scenario": {"horizon_slots": 1}})
    with pytest.raises(ValueError, match="seed=-1 is invalid"):
        gym.make(ENV_ID, backend="kinematic").reset(seed=-1)
    for make in (lambda: gym.make(ENV_ID, backend="kinematic"), lambda: gym.make_vec(ENV_ID, 2)):
        with pytest.raises(ValueError, match=r"seed=4294967296 is invalid: accepted an integer"):
            make().reset(seed=2**32)
    env.reset(seed=0)
    *_, trunc, _ = env.step(np.array([5, 3, 0, 0]))
    assert trunc
    for _ in range(2):  # the same clear error every time, no silent auto-reset
        with pytest.raises(RuntimeError, match="call reset"):
            env.step(np.array([5, 3, 0, 0]))


@FAST
@given(
    section=st.sampled_from(["motion", "acoustics", "network", "physics", "scenario"]),
    key=st.sampled_from(
        ["v_max_mps", "p_tx_w", "aoi_max", "timestep_s", "slot_s", "k_reset", "n_auvs", "x"]
    ),
    value=st.one_of(
        st.floats(allow_nan=True, allow_infinity=True),
        st.integers(-10, 10**6),
        st.text(max_size=5),
        st.none(),
        st.lists(st.floats(), max_size=3),
    ),
)
def test_any_config_value_is_accepted_valid_or_refused_clearly(section, key, value):
    try:
        cfg = Config.from_dict({section: {key: value}})
    except ConfigError as exc:
        assert section in str(exc) or key in str(exc)
        return
    numbers = json.dumps(cfg.to_dict())
    assert "NaN" not in numbers and "Infinity" not in numbers


@FAST
@given(text=st.text(max_size=200))
def test_any_yaml_text_loads_as_a_mapping_or_a_clear_error(tmp_path_factory, text):
    path = tmp_path_factory.mktemp("y") / "c.yaml"
    path.write_text(text)
    try:
        data = load_mapping(path, "config file")
    except ConfigError as exc:
        assert "c.yaml" in str(exc)
        return
    assert isinstance(data, dict)


@FAST
@given(action=st.lists(st.integers(-3, 15), min_size=0, max_size=10))
def test_any_action_is_applied_or_refused_with_its_field(action):
    env = gym.make(ENV_ID, backend="kinematic", n_auvs=2, n_nodes=7)
    env.reset(seed=0)
    a = np.array(action)
    try:
        obs, *_ = env.step(a)
    except ActionError as exc:
        assert "accepted" in str(exc)
        assert not env.action_space.contains(a.astype(np.int64))
        return
    assert env.action_space.contains(a.astype(np.int64)) and np.isfinite(obs).all()
