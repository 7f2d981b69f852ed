"""One scenario resolution (`scenarios.resolve`): a config's own nodes are kept by every
entry point, contradictions name both sides, nodes come from lists or CSV files."""

import json

import gymnasium as gym
import numpy as np
import pytest
from conftest import ROOT

import iout_mj
from iout_mj.backends.registry import BACKENDS
from iout_mj.config import Config
from iout_mj.envs import ENV_ID, KinematicVecEnv
from iout_mj.paper import PAPER_LAYOUTS
from iout_mj.scenarios import EnvSpec, given_keys, load_config, resolve
from iout_mj.schema import ConfigError, build_dataclass
from iout_mj.training.config import TrainConfig

NODES = [(120.0, 80.0), (640.0, 310.0), (450.0, 880.0), (260.0, 610.0), (910.0, 150.0)]


@pytest.fixture
def custom(tmp_path):
    path = tmp_path / "custom.yaml"
    rows = "\n".join(f"    - [{x}, {y}]" for x, y in NODES)
    path.write_text(f"scenario:\n  nodes_m:\n{rows}\n")
    return path


def _nodes(env) -> list:
    return [tuple(p) for p in env.unwrapped.mission.network.nodes_m.tolist()]


def test_every_entry_point_keeps_a_config_files_own_nodes(custom):
    single = gym.make(ENV_ID, backend="kinematic", n_auvs=1, config=str(custom))
    assert _nodes(single) == NODES and single.unwrapped.mission.n_auvs == 1
    for seed in (0, 1):  # the same nodes in every episode
        single.reset(seed=seed)
        assert _nodes(single) == NODES
    venv = KinematicVecEnv(3, n_auvs=3, config=custom, seed=0)
    venv.reset()
    assert (venv.mission.network.nodes_m == np.array(NODES)).all()
    vec = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="vector_entry_point", config=custom)
    assert vec.unwrapped.mission.n_nodes == 5
    marl = iout_mj.parallel_env(config=str(custom), n_auvs=3)
    assert (marl.mission.n_auvs, marl.mission.n_nodes) == (3, 5)
    train = build_dataclass(
        TrainConfig, {"env": {"scenario": {"nodes_m": NODES}}, "n_auvs": 1}, "t"
    )
    assert train.env_spec.layout == "custom" and train.env_spec.config.scenario.nodes_m == tuple(
        NODES
    )


@pytest.mark.parametrize(
    ("keywords", "message"),
    [
        ({"n_nodes": 7}, r"n_nodes=7 contradicts config .*custom.yaml, which sets 5 nodes"),
        ({"layout": "random"}, r"layout='random' contradicts .* its own 5 nodes"),
        ({"layout": "paper"}, r"layout='paper' contradicts"),
    ],
)
def test_a_keyword_that_contradicts_the_files_nodes_names_both(custom, keywords, message):
    with pytest.raises(ConfigError, match=message):
        resolve(str(custom), **keywords)


def test_a_file_that_sets_n_auvs_refuses_another(tmp_path):
    path = tmp_path / "n3.yaml"
    path.write_text("scenario:\n  n_auvs: 3\n")
    assert resolve(str(path)).n_auvs == 3
    assert resolve(str(path), n_auvs=3).n_auvs == 3
    with pytest.raises(
        ConfigError, match=r"n_auvs=2 contradicts config .*n3.yaml, which sets n_auvs=3"
    ):
        resolve(str(path), n_auvs=2)


def test_paper_layout_means_the_papers_nodes_or_one_seeded_layout_per_k():
    assert resolve(n_nodes=13).config.scenario.nodes_m == PAPER_LAYOUTS[13]
    nine = resolve(n_nodes=9).config.scenario.nodes_m
    assert len(nine) == 9 and nine == resolve(n_nodes=9, n_auvs=3).config.scenario.nodes_m
    assert resolve(n_nodes=9, layout="random").random_per_episode


def test_nodes_from_a_csv_file(tmp_path):
    path = tmp_path / "nodes.csv"
    path.write_text("x_m, y_m\n# a comment\n" + "\n".join(f"{x}, {y}" for x, y in NODES) + "\n")
    spec = resolve(nodes=path, n_auvs=2)
    assert spec.layout == "custom" and spec.config.scenario.nodes_m == tuple(NODES)
    env = gym.make(ENV_ID, backend="kinematic", nodes=str(path))
    assert _nodes(env) == NODES


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("1, 2\n3, x\n", r"nodes.csv:2: '3, x' is not a row of numbers"),
        ("100, 200, 30, 1\n400, 500, 40, 1\n", r"4 values; accepted 'x, y' or 'x, y, z'"),
        ("100, 200\n", r"nodes_m"),  # one node: the config's own bounds say 2 to 30
        ("100, 200\n5000, 10\n", r"nodes_m\[1\]"),  # outside the area
    ],
)
def test_a_bad_nodes_file_says_what_is_wrong(tmp_path, text, message):
    path = tmp_path / "nodes.csv"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        resolve(nodes=path)


def test_a_resolved_spec_passes_through_and_refuses_contradictions():
    spec = resolve(n_auvs=3, n_nodes=9)
    assert resolve(spec, backend="mujoco") == EnvSpec(spec.config, "paper", "mujoco")
    assert resolve(spec, n_auvs=3).config == spec.config
    with pytest.raises(ConfigError, match=r"\{'n_nodes': 7\} contradicts"):
        resolve(spec, n_nodes=7)


def test_the_backend_registry_is_what_every_entry_point_accepts():
    assert set(BACKENDS) == {"mujoco", "kinematic", "warp"}
    with pytest.raises(ConfigError, match=r"backend='jax' is invalid: accepted one of"):
        resolve(backend="jax")
    with pytest.raises(ValueError, match=r"warp steps batches"):
        gym.make(ENV_ID, backend="warp")


@pytest.mark.slow
def test_your_own_network_end_to_end_from_a_csv(tmp_path, cli):
    """The README's walkthrough, shortened: a CSV of nodes to a trained policy, an evaluation
    on those nodes and a mission video of them."""
    nodes = tmp_path / "nodes.csv"
    nodes.write_text("x_m, y_m\n" + "\n".join(f"{x}, {y}" for x, y in NODES) + "\n")
    run = tmp_path / "run"
    cli(
        "train",
        "training/configs/smoke.yaml",
        "--nodes-file",
        nodes,
        "--n-auvs",
        "2",
        "--steps",
        "128",
        "--out",
        run,
        cwd=ROOT,
    )
    saved = TrainConfig.load(run / "config.yaml")  # what the run trained on
    assert saved.env_spec.n_auvs == 2 and saved.env_spec.config.scenario.nodes_m == tuple(NODES)
    out = cli(
        "evaluate",
        "--policy",
        run / "best",
        "greedy",
        "--nodes-file",
        nodes,
        "--n-auvs",
        "2",
        "--episodes",
        "2",
        "--backend",
        "kinematic",
        "--json",
        "--out",
        tmp_path / "eval",
    )
    rows = json.loads(out.stdout)
    assert {(r["n_nodes"], r["layout"]) for r in rows} == {(5, "custom")} and len(rows) == 2
    cli("figures", "--results", tmp_path / "eval", "--out", tmp_path / "fig")
    assert list((tmp_path / "fig").glob("*.png"))
    mission = cli(
        "mission",
        "--policy",
        run / "best",
        "--nodes-file",
        nodes,
        "--n-auvs",
        "2",
        "--backend",
        "kinematic",
        "--slots",
        "3",
        "--width",
        "320",
        "--height",
        "180",
        "--out",
        tmp_path / "mission",
    )
    assert json.loads(mission.stdout)["n_nodes"] == 5
    assert (tmp_path / "mission" / "mission.mp4").stat().st_size > 0


@pytest.mark.slow
@pytest.mark.parametrize("backend", list(BACKENDS))
def test_every_registered_backend_steps_a_batch_of_the_same_scenario(backend):
    if BACKENDS[backend].extra is not None:
        pytest.importorskip("mujoco_warp")
    from iout_mj.envs.batch import MissionBatch

    batch = MissionBatch(2, backend, n_auvs=2, config={"scenario": {"nodes_m": NODES}}, seed=0)
    assert batch.env_spec.layout == "custom" and batch.env_spec.backend == backend
    batch.restart()
    rewards, failed = batch.move(np.tile([5, 3, 0, 1] * 2, (2, 1)))
    assert np.isfinite(rewards).all() and not failed.any()
    assert (batch.mission.network.nodes_m == np.array(NODES)).all()


def test_several_env_configs_combine_section_by_section_later_ones_winning(tmp_path):
    realistic = ROOT / "training/configs/env/realistic-channel.yaml"
    wenz = ROOT / "training/configs/env/wenz.yaml"
    both = load_config([realistic, wenz])
    assert both.channel == load_config(realistic).channel
    assert both.acoustics == load_config(wenz).acoustics
    flat = load_config([wenz, {"acoustics": {"noise_model": "flat"}}])
    assert flat.acoustics.noise_model == "flat"
    mine = {"scenario": {"n_auvs": 1}, "physics": {"vehicle": "remus100"}}
    assert given_keys([realistic, mine]) == {"n_auvs"}
    assert load_config([realistic, mine]).motion == Config().with_vehicle("remus100").motion
    assert load_config([]) == Config()
    with pytest.raises(ConfigError, match=r"config\[1\]=3: accepted a file path or a dict"):
        load_config([wenz, 3])
