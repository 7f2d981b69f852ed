"""Config: defaults, presets, round trips, and a clear error for each kind of bad input."""

import dataclasses
import json
import os
from pathlib import Path

import numpy as np
import pytest
import yaml

from iout_mj.config import PAPER_LAYOUTS, Config, MotionConfig, RewardWeights
from iout_mj.experiments.ray_jobs import load_sweep
from iout_mj.scenarios import fixed_config, load_config, make_config, random_layout, resolve
from iout_mj.schema import ConfigError, load_mapping
from iout_mj.training import TrainConfig
from iout_mj.training.marl import MarlConfig


def test_paper_defaults():
    cfg = Config()
    assert cfg.motion.drag_factor_nspm2 == pytest.approx(9.0)
    assert cfg.scenario.horizon_slots == 55 and cfg.scenario.slot_s == 25
    assert cfg.acoustics.f_wet_khz == 70 and cfg.acoustics.f_data_khz == 50
    assert cfg.network.k_reset == 3


@pytest.mark.parametrize("suffix", [".yaml", ".json"])
def test_round_trip(tmp_path, suffix):
    cfg = make_config(3, 13)
    path = tmp_path / f"c{suffix}"
    cfg.save(path)
    assert Config.load(path) == cfg


# The paper's layouts as DESIGN.md section 4 lists them (the authors' code), metres.
PAPER_7 = ((100, 100), (800, 500), (500, 900), (300, 700), (500, 200), (900, 200), (200, 400))
PAPER_13 = (
    *((100, 100), (800, 500), (500, 900), (300, 700), (200, 400), (900, 200), (500, 200)),
    *((700, 800), (800, 200), (700, 300), (700, 100), (300, 100), (900, 700)),
)


def assert_seeded_layout(nodes_m, k):
    """K nodes inside the 1000 m area, at least 80 m apart, outside the dock zone (70 m
    around (830, 830))."""
    nodes = np.array(nodes_m)
    assert nodes.shape == (k, 2)
    assert np.all((nodes >= 0) & (nodes <= 1000))
    dist = np.linalg.norm(nodes[:, None] - nodes[None], axis=2) + np.eye(k) * 1e9
    assert dist.min() >= 80.0
    assert np.all(np.linalg.norm(nodes - [830, 830], axis=1) > 70)


def test_presets_and_random_layouts():
    assert make_config(1, 13).scenario.nodes_m == PAPER_13
    assert make_config(3, 7).scenario.nodes_m == PAPER_7
    assert set(PAPER_LAYOUTS) == {7, 13}
    for k in (2, 9, 30):
        assert_seeded_layout(random_layout(k, seed=k), k)
    assert random_layout(9, seed=1) == random_layout(9, seed=1)
    assert random_layout(9, seed=1) != random_layout(9, seed=2)


@pytest.mark.parametrize(
    ("data", "match"),
    [
        ({"motion": {"v_max": 4}}, r"unknown key.*v_max"),
        ({"motion": {"v_max_mps": "fast"}}, r"v_max_mps.*wrong type.*number"),
        ({"motion": {"heading_levels": 11.5}}, r"heading_levels.*wrong type.*integer"),
        (
            {"acoustics": {"p_tx_w": -5}},
            r"^config\.acoustics\.p_tx_w=-5.0 is invalid: accepted a number in \[0.001, 1e\+06\]$",
        ),
        ({"acoustics": {"eta_tx": 1.5}}, r"eta_tx=1.5 is invalid: accepted a number in \[0.01, 1"),
        ({"motion": {"prop_efficiency": 0}}, r"prop_efficiency"),
        ({"scenario": {"nodes_m": [[100, 100]]}}, r"nodes_m.*2 to 30 nodes"),
        ({"scenario": {"dock_center_m": [990, 500]}}, r"dock_center_m.*inside area_m"),
        ({"scenario": {"n_auvs": 5}}, r"n_auvs=5.*1 to 4"),
        ({"scenario": {"dock_max_speed_mps": 0}}, r"dock_max_speed_mps=0.0.*> 0 m/s, or null"),
        ({"scenario": {"nodes_m": [[100, 100], [2000, 5]]}}, r"nodes_m\[1\].*inside area_m"),
        ({"acoustics": {"noise_model": "loud"}}, r"noise_model.*'flat' or 'wenz'"),
        ({"scenario": {"area_m": [1000]}}, r"area_m.*list of 2 values"),
        ([1, 2], r"wrong type: accepted a mapping"),
    ],
)
def test_bad_input_names_field_value_and_accepted(data, match):
    with pytest.raises(ConfigError, match=match):
        Config.from_dict(data)


def test_bad_files(tmp_path):
    with pytest.raises(ConfigError, match="does not exist"):
        Config.load(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("motion: [unclosed")
    with pytest.raises(ConfigError, match="not valid YAML/JSON"):
        Config.load(bad)
    with pytest.raises(ConfigError, match="accepted suffixes"):
        Config().save(tmp_path / "c.txt")
    ok = tmp_path / "partial.json"
    ok.write_text(json.dumps({"motion": {"hotel_power_w": 20}}))
    assert Config.load(ok).motion.hotel_power_w == 20.0


def test_make_config_errors():
    with pytest.raises(ConfigError, match="layout='random'"):
        make_config(2, 9, layout="paper")
    with pytest.raises(ConfigError, match="layout='grid'"):
        make_config(2, 7, layout="grid")


def test_frozen():
    with pytest.raises(AttributeError):
        MotionConfig().v_max_mps = 5  # type: ignore[misc]


def test_reward_weights_carry_their_signs():
    w = RewardWeights()
    costs = ("aoi", "fairness", "boundary", "stall", "infeasible_uplink", "collision")
    assert all(getattr(w, name) < 0 for name in (*costs, "undocked_at_end"))
    cfg = Config.from_dict({"reward": {"weights": {"aoi": -0.5}, "stall_distance_m": 2.0}})
    assert cfg.reward.weights.aoi == -0.5 and cfg.reward.stall_distance_m == 2.0
    with pytest.raises(ConfigError, match="unknown key"):
        Config.from_dict({"reward": {"aoi": 0.1}})  # weights live under reward.weights
    with pytest.raises(ConfigError, match=r"weights\.aoi"):
        Config.from_dict({"reward": {"weights": {"aoi": "high"}}})


def test_one_scenario_resolution_for_every_entry_point():
    assert resolve(None, 1, 13).config.scenario.nodes_m == PAPER_13
    assert resolve(None, 1, 13).config.scenario.n_auvs == 1
    fixed = fixed_config(2, 5)  # evaluation, mission, bench: one seeded layout per K
    assert_seeded_layout(fixed.scenario.nodes_m, 5)
    base = Config.from_dict({"motion": {"hotel_power_w": 20}})
    for other in (fixed_config(2, 5), fixed_config(4, 5), fixed_config(1, 5, base)):
        assert other.scenario.nodes_m == fixed.scenario.nodes_m  # the same for any N and base
    assert fixed_config(2, 6).scenario.nodes_m[:5] != fixed.scenario.nodes_m
    paper = fixed_config(2, 7)  # the paper's nodes, every other field the defaults
    assert paper.scenario.nodes_m == PAPER_7 and paper.scenario.n_auvs == 2
    assert paper.replace(scenario=Config().scenario) == Config()
    assert dataclasses.replace(paper.scenario, nodes_m=PAPER_7) == Config().scenario
    assert fixed_config(1, 9, base).motion.hotel_power_w == 20.0
    with pytest.raises(ConfigError, match="layout='grid'"):
        resolve(None, 2, 7, "grid")


@pytest.mark.parametrize(
    ("data", "match"),
    [
        ({"reward": {"collision_sigma_m": 1e-200}}, r"collision_sigma_m=1e-200.*\[0.1, 20000\]"),
        ({"acoustics": {"f_data_khz": 1e4}}, r"f_data_khz=10000.0.*\[0.1, 200\]"),
        ({"reward": {"weights": {"aoi": 1e308}}}, r"weights\.aoi=1e\+308.*\[-1e\+06, 1e\+06\]"),
        ({"acoustics": {"data_rate_bps": 2e6}}, r"data_rate_bps=2000000.0.*\[1, 64000\]"),
        ({"network": {"k_reset": 2**63}}, r"k_reset=9223372036854775808.*\[1, 10000\]"),
        ({"scenario": {"horizon_slots": 10**9}}, r"horizon_slots=1000000000.*\[1, 10000\]"),
        ({"physics": {"timestep_s": 1e-6}}, r"timestep_s=1e-06.*\[0.001, 0.25\]"),
        ({"motion": {"heading_levels": 10**9 + 1}}, r"heading_levels=1000000001.*3 to 101"),
        (
            {"motion": {"v_max_mps": 1}, "physics": {"current_mps": [3, 0]}},
            r"current_mps=\(3.0, 0.0\).*out-run.*v_max_mps=1",
        ),
    ],
)
def test_configs_that_broke_the_model_are_refused_with_field_value_and_range(data, match):
    with pytest.raises(ConfigError, match=match):
        Config.from_dict(data)


CONFIGS = Path(__file__).parents[1] / "training" / "configs"


def test_every_shipped_config_loads():
    env_configs = sorted((CONFIGS / "env").glob("*.yaml"))
    marl_configs = [*CONFIGS.glob("mappo-*.yaml"), *CONFIGS.glob("ippo-*.yaml")]
    marl_configs.append(CONFIGS / "smoke-mappo.yaml")
    train_configs = [*CONFIGS.glob("ppo-*.yaml"), *CONFIGS.glob("smoke*.yaml")]
    train_configs = [p for p in train_configs if p not in marl_configs]
    assert len(env_configs) >= 3 and len(train_configs) >= 6 and len(marl_configs) >= 5
    overlays = {"realistic-channel-bellhop.yaml": "realistic-channel.yaml"}  # file: its base
    for path in env_configs:
        base = overlays.get(path.name)
        load_config([path] if base is None else [path.with_name(base), path])
    for path in train_configs:
        TrainConfig.load(path)
    for path in marl_configs:
        MarlConfig.load(path)
    load_sweep(CONFIGS / "sweep-smoke.yaml")
    assert load_mapping(CONFIGS / "rl-zoo3-ppo.yml", "rl-zoo3 file")


def test_a_training_config_s_env_is_completed_as_an_env_config_file_is(tmp_path):
    """`env: {physics: {vehicle: remus100}}` in a training config flies the REMUS at its own
    V_max (it trained at the torpedo's 4 m/s before), and nodes with a z column give depths."""
    env = {
        "physics": {"vehicle": "remus100"},
        "scenario": {"nodes_m": [[100.0, 200.0, 80.0], [300.0, 400.0, 90.0]]},
    }
    path = tmp_path / "t.yaml"
    path.write_text(yaml.safe_dump({"name": "t", "n_auvs": 1, "env": env}))
    train = TrainConfig.load(path)
    assert train.env == Config.from_dict(env)
    assert train.env.motion.v_max_mps == Config().with_vehicle("remus100").motion.v_max_mps < 4.0
    assert train.env.channel.node_depths_m == (80.0, 90.0)


def test_a_variant_config_is_its_base_with_its_own_keys_merged_in(tmp_path):
    """`base:` names the config a file varies (from the file's folder): mappings merge key by
    key, other values replace the base's; the shipped variants resolve to full configs."""
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "a.yaml").write_text(
        "name: a\nn_auvs: 2\nphases: [{backend: kinematic, timesteps: 100}]\n"
        "env: {physics: {current_jitter_mps: 0.5}, reward: {weights: {aoi: -0.2}}}\n"
    )
    (tmp_path / "b.yaml").write_text(
        "base: sub/a.yaml\nname: b\nenv: {reward: {weights: {energy_margin: 0.0}}}\n"
    )
    b = TrainConfig.load(tmp_path / "b.yaml")
    assert (b.name, b.n_auvs, b.total_timesteps) == ("b", 2, 100)
    assert b.env.physics.current_jitter_mps == 0.5
    assert (b.env.reward.weights.aoi, b.env.reward.weights.energy_margin) == (-0.2, 0.0)
    assert b.env.reward.weights.dock_all == RewardWeights().dock_all != 0.0
    aoi = TrainConfig.load(CONFIGS / "ppo-general-n3-aoi.yaml")
    default = TrainConfig.load(CONFIGS / "ppo-general-n3.yaml")
    assert aoi.n_auvs == 3 and aoi.imitation == default.imitation is not None
    assert aoi.env.reward.weights.aoi == 10 * default.env.reward.weights.aoi
    assert MarlConfig.load(CONFIGS / "mappo-n4.yaml").n_auvs == 4


def test_a_symlink_loop_as_a_config_or_its_base_is_refused_with_a_message(tmp_path):
    (tmp_path / "a.yaml").symlink_to(tmp_path / "b.yaml")
    (tmp_path / "b.yaml").symlink_to(tmp_path / "a.yaml")
    (tmp_path / "c.yaml").write_text("base: a.yaml\nname: c\n")
    for name in ("a.yaml", "c.yaml"):
        with pytest.raises(ConfigError, match=r"a.yaml cannot be opened"):
            TrainConfig.load(tmp_path / name)


@pytest.mark.parametrize(
    ("files", "match"),
    [
        ({"a.yaml": "base: a.yaml\nname: a\n"}, r"a.yaml is its own base"),
        ({"a.yaml": "base: b.yaml\n", "b.yaml": "base: a.yaml\n"}, r"is its own base"),
        ({f"c{i}.yaml": f"base: c{i + 1}.yaml\n" for i in range(10)}, "more than 8 deep"),
        ({"a.yaml": "base: gone.yaml\n"}, r"gone.yaml does not exist"),
        ({"a.yaml": "base: [x.yaml]\n"}, r"base=\['x.yaml'\] is invalid: accepted the path"),
        ({"a.yaml": "base: ''\n"}, r"base='' is invalid"),
    ],
)
def test_a_bad_base_is_refused_with_a_message(tmp_path, files, match):
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    first = next(iter(files))
    with pytest.raises(ConfigError, match=match):
        TrainConfig.load(tmp_path / first)
    with pytest.raises(ConfigError, match=match):
        MarlConfig.load(tmp_path / first)


def test_the_realistic_channel_training_config_trains_on_the_shipped_channel():
    """The training config repeats the env file's channel block; the two must not drift."""
    env = Config.load(CONFIGS / "env" / "realistic-channel.yaml")
    train = TrainConfig.load(CONFIGS / "ppo-general-n2-realistic-channel.yaml")
    assert train.env.channel == env.channel
    assert train.env.channel.features  # the channel is on, not the paper's default


@pytest.mark.parametrize(
    ("name", "text", "match"),
    [
        ("dup.yaml", "motion:\n  v_max_mps: 2\n  v_max_mps: 3\n", r"key 'v_max_mps' appears twice"),
        ("dup.json", '{"motion": {"v_max_mps": 2, "v_max_mps": 3}}', r"'v_max_mps' appears twice"),
        ("deep.yaml", "a: " + "[" * 400_000 + "]" * 400_000, "nested deeper than 32"),
        ("deep.json", '{"a": ' + "[" * 400_000 + "]" * 400_000 + "}", "nested deeper than 32"),
        ("self.yaml", "a: &a [*a]\n", "contains itself"),
        (
            "doubling.yaml",
            "a0: &a0 [1]\n"
            + "".join(f"a{i}: &a{i} [*a{i - 1}, *a{i - 1}]\n" for i in range(1, 31)),
            "more than 100000 values",
        ),
    ],
)
def test_duplicate_keys_deep_nesting_and_expansion_are_refused(tmp_path, name, text, match):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(ConfigError, match=rf"{name}: .*{match}"):
        Config.load(path)


def test_a_merge_key_may_be_overridden_and_json_strings_hold_brackets(tmp_path):
    path = tmp_path / "merge.yaml"
    path.write_text("base: &b {v_max_mps: 2}\nmotion:\n  <<: *b\n  v_max_mps: 3\n")
    assert load_mapping(path, "f")["motion"] == {"v_max_mps": 3}
    path = tmp_path / "brackets.json"
    path.write_text(json.dumps({"name": "[[[[" * 20 + '\\"{{' * 20}))
    assert load_mapping(path, "f")["name"].startswith("[[[[")


def test_non_regular_files_are_refused_with_a_message(tmp_path):
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)  # opening it for reading would block without O_NONBLOCK
    cases = {fifo: "is a FIFO", tmp_path: "is a directory", Path("/dev/null"): "character device"}
    if Path("/proc/self/pagemap").exists():  # a regular /proc file that reads forever
        cases[Path("/proc/self/pagemap")] = "cannot be read|larger than"
    for path, match in cases.items():
        with pytest.raises(ConfigError, match=match) as err:
            Config.load(path)
        assert str(path) in str(err.value)
