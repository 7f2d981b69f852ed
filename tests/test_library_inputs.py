"""The library's Python entry points, called directly: bad input gets one clear error naming
what is accepted, never a numpy, torch or MuJoCo error from deep inside, a silent broadcast or
a non-finite result."""

import json

import gymnasium as gym
import numpy as np
import pytest

from iout_mj.agents.policies import load_policy, resolve_policy_folder, split_search
from iout_mj.agents.policy_format import load_policy_folder
from iout_mj.agents.registry import make_policy
from iout_mj.agents.search import RolloutSearch
from iout_mj.backends.kinematic import KinematicEnvironment
from iout_mj.backends.mujoco.physics import AUVPhysics, Stepper
from iout_mj.config import Config, MotionConfig, ScenarioConfig
from iout_mj.envs import ENV_ID
from iout_mj.errors import PolicyError, PolicyMismatchError, ResultFileError, UsageError
from iout_mj.experiments import compare, evaluate, statistics
from iout_mj.scenarios import fixed_config, make_config, resolve
from iout_mj.schema import ConfigError
from iout_mj.training import TrainConfig
from iout_mj.training.config import PhaseConfig
from iout_mj.training.marl import MarlConfig, MarlPhase

INTEGER = "accepted an integer from"


# ------------------------------------------------------------------ scenarios
@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: make_config(2.5, 7), "n_auvs=2.5 is invalid"),  # was a slicing TypeError
        (lambda: make_config(True, 7), "n_auvs=True is invalid"),  # was taken as N = True
        (lambda: make_config(2, 5.5, "random"), "n_nodes=5.5 is invalid"),  # "place 5.5 nodes"
        (lambda: make_config(2, "5", "random"), "n_nodes='5' is invalid"),
        (lambda: make_config(2, 5, "random", seed=-1), "seed=-1 is invalid"),  # numpy's message
        (lambda: make_config(2, 5, "random", seed=1.5), "seed=1.5 is invalid"),
        (lambda: fixed_config(1, None), "n_nodes=None is invalid"),
        (lambda: resolve(None, 2.0, 7), "n_auvs=2.0 is invalid"),
        (lambda: resolve(None, 2, "7"), "n_nodes='7' is invalid"),
    ],
)
def test_scenarios_refuse_counts_and_seeds_that_are_not_integers_in_range(call, match):
    with pytest.raises(ConfigError, match=match) as err:
        call()
    assert INTEGER in str(err.value)


def test_scenarios_take_numpy_integers():
    spec = resolve(None, np.int64(2), np.int64(5), "random")
    assert (spec.n_auvs, spec.n_nodes) == (2, 5) and type(spec.n_auvs) is int


# ------------------------------------------------------------------ agents
@pytest.fixture(scope="module")
def envs():
    """A reset kinematic env (K = 7) per N = 1, 2."""
    made = {n: gym.make(ENV_ID, backend="kinematic", n_auvs=n, n_nodes=7) for n in (1, 2)}
    for env in made.values():
        env.reset(seed=0)
    yield made
    for env in made.values():
        env.close()


@pytest.fixture(scope="module")
def env_n1(envs):
    return envs[1]


@pytest.fixture(scope="module")
def env_n2(envs):
    return envs[2]


def test_baselines_refuse_bad_names_and_seeds():
    with pytest.raises(PolicyError, match="unknown policy"):
        make_policy(["greedy"])  # was TypeError: unhashable type
    for seed in (-1, 1.5, "x"):  # numpy's "expected non-negative integer", or taken
        with pytest.raises(UsageError, match=r"seed=.* is invalid: accepted an integer from 0"):
            make_policy("random-walk", seed)
    assert make_policy("random-walk", None).name == "random-walk"


@pytest.mark.parametrize("suffix", ["-1", "1.5", "\u0663", "x"])
def test_a_malformed_search_suffix_is_refused(suffix):
    # "+rollout-1" was looked up as a folder; "+rollout<Arabic-Indic 3>" flew 3 candidates
    with pytest.raises(PolicyError, match="C from 1 to 1024"):
        split_search("ppo-general+rollout" + suffix)
    assert split_search("runs/a+rollout7") == ("runs/a", 7)


def test_load_policy_refuses_a_name_that_is_not_a_string(env_n2):
    with pytest.raises(PolicyError, match="non-empty string"):
        load_policy(None, env_n2)  # was TypeError from the regular expression


def test_a_trained_policy_refuses_an_observation_of_another_scenario(env_n1, env_n2):
    policy = load_policy("ppo-n2-k7", env_n2)
    obs = env_n2.unwrapped.mission.flat_observation()
    assert policy(env_n2, obs).shape == (8,)
    with pytest.raises(PolicyMismatchError, match=r"shape \(29,\).*observes 43 entries"):
        policy(env_n1, env_n1.unwrapped.mission.flat_observation())  # a broadcasting error
    for bad in (np.nan, np.inf):  # NaN was a torch error; inf was clipped into an action
        with pytest.raises(PolicyError, match="NaN or infinity"):
            policy.act(np.full_like(obs, bad))
    general = load_policy("ppo-general-n2", env_n2)
    with pytest.raises(PolicyMismatchError, match="N=2, K up to 30"):
        general(env_n1, None)


def test_the_rollout_search_checks_its_candidates_seed_and_scenario(env_n1):
    base = load_policy_folder(resolve_policy_folder("ppo-general-n2"))
    for count in (0, 2.5, True, "3", 10**6):  # 2.5 flew 2, 10**6 was taken
        with pytest.raises(UsageError, match=f"candidates=.* is invalid: {INTEGER} 1 to 1024"):
            RolloutSearch(base, count)
    with pytest.raises(UsageError, match="seed=-1 is invalid"):
        RolloutSearch(base, 4, -1)
    search = RolloutSearch(base, 4)
    with pytest.raises(PolicyMismatchError, match=r"shape \(1, 314\)"):
        search(env_n1, None)  # the search's own normaliser call: a broadcasting error


# ------------------------------------------------------------------ evaluate
EVALUATE = {
    "n_auvs": [1],
    "nodes": [7],
    "episodes": 1,
    "seed": 0,
    "backend": "kinematic",
    "workers": 1,
    "progress": False,
}


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"policies": "greedy"}, "accepted a non-empty list"),  # "policy e given twice"
        ({"policies": []}, "accepted a non-empty list"),  # "no policy can serve ...: "
        ({"n_auvs": 1}, "n_auvs=1: accepted a list"),  # 'int' object is not iterable
        ({"episodes": 1.5}, "episodes=1.5 is invalid"),  # a TypeError from range()
        ({"seed": 2**64}, "seed=18446744073709551616 is invalid"),  # numpy's, in a worker
        ({"seed": 2**32 - 1, "episodes": 2}, "episode seeds run to 4294967296"),
        ({"training_seeds": [1.5]}, r"training_seeds\[0\]=1.5 is invalid"),  # was taken
    ],
)
def test_evaluate_checks_its_arguments_before_any_work(changes, match):
    kwargs = {"policies": ["greedy"], **EVALUATE, **changes}
    with pytest.raises(UsageError, match=match):
        evaluate.evaluate(**kwargs)


def test_evaluate_still_flies_and_save_refuses_no_rows(tmp_path):
    rows, episodes = evaluate.evaluate(["greedy"], **EVALUATE)
    assert len(rows) == len(episodes) == 1 and np.isfinite(rows[0]["mean_aoi_horizon"])
    with pytest.raises(UsageError, match="no summary rows"):
        evaluate.save([], [], tmp_path / "out")  # was an IndexError
    assert not (tmp_path / "out").exists()
    bad = [{**rows[0], "mean_aoi_horizon": float("nan")}]
    with pytest.raises(UsageError, match=r"non-finite number.*accepted finite metrics"):
        evaluate.save(bad, episodes, tmp_path / "out")  # was written as a bare NaN
    assert not (tmp_path / "out").exists()
    evaluate.save(rows, episodes, tmp_path / "out")
    assert json.loads((tmp_path / "out" / "results.json").read_text()) == rows


# ------------------------------------------------------------------ statistics, compare
RUNS = np.array([5.0, 6.0, 7.0, 8.0, 9.0])


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: statistics.iqm(RUNS[:, None], reps=0), "reps=0 is invalid"),  # IndexError
        (lambda: statistics.iqm(RUNS[:, None], reps=2.5), "reps=2.5 is invalid"),
        (lambda: statistics.iqm(RUNS[:, None], seed=2**32), "seed=4294967296 is invalid"),
        (lambda: statistics.iqm(np.zeros((0, 1))), r"shape \(0, 1\)"),  # a NaN interval
        (lambda: statistics.iqm(RUNS), r"shape \(5,\)"),  # IndexError
        (lambda: statistics.iqm(np.array([[np.nan], [1.0]])), "NaN or infinity"),  # NaN out
        (lambda: statistics.cells_iqm([]), "no score matrix"),  # AttributeError in rliable
        (lambda: statistics.cells_improvement([RUNS], [RUNS, RUNS]), "1 cells of the policy"),
        (lambda: statistics.comparison([RUNS], [0 * RUNS]), "AoI <= 0"),  # ZeroDivisionError
        (lambda: statistics.score_matrix([], "x"), "no cell of x"),
        # different tasks answered P = 0.5
        (
            lambda: statistics.probability_of_improvement(np.ones((5, 2)), np.ones((5, 3))),
            "2 tasks of the policy and 3 of the reference",
        ),
    ],
)
def test_statistics_refuse_what_rliable_cannot_estimate(call, match):
    with pytest.raises(UsageError, match=match):
        call()


def _results() -> tuple[list[dict], list[dict]]:
    cell = {"n_auvs": 1, "n_nodes": 7, "layout": "paper", "backend": "kinematic"}
    rows = [
        {"policy": p, **cell, "mean_aoi_horizon": a, "docking_rate": 1.0, "delivered_bits": 1e6}
        for p, a in (("p", 7.0), ("greedy", 8.0))
    ]
    episodes = [
        {"policy": p, **cell, "seed": s, "training_seed": None, "mean_aoi_horizon": 5.0 + s + d}
        for p, d in (("p", 0.0), ("greedy", 1.0))
        for s in range(5)
    ]
    return rows, episodes


def test_compare_refuses_repeated_episodes_and_a_policy_against_itself():
    rows, episodes = _results()
    ok = compare.compare(rows, episodes, "p", "greedy", reps=50)
    assert ok["aggregate"]["runs_per_cell"] == 5
    with pytest.raises(ResultFileError, match="episode seed 0, training seed None more than"):
        compare.compare(rows, episodes + episodes, "p", "greedy", reps=50)  # 10 runs, a CI
    with pytest.raises(UsageError, match="both 'p'"):
        compare.compare(rows, episodes, "p", "p", reps=50)  # P = 0.5, ratio 1


# ------------------------------------------------------------------ backends
@pytest.fixture(scope="module")
def physics():
    p = AUVPhysics.from_config(fixed_config(2, 7))
    yield p
    p.free()


def test_physics_refuses_bad_step_counts_setpoints_and_scenes(physics):
    xy, zeros = np.array([[100.0, 100.0], [200.0, 200.0]]), np.zeros(2)
    physics.set_poses(xy, zeros, np.ones(2))
    for nstep in (0, -1, 1.5, True):  # IndexError, numpy's, TypeErrors
        with pytest.raises(UsageError, match=f"nstep=.* is invalid: {INTEGER} 1 to 10000"):
            physics.step(nstep)
    with pytest.raises(ValueError, match="yaw_setpoint_rad holds NaN"):
        physics.set_commands(np.array([np.nan, 0.0]), np.ones(2))  # MuJoCo reset later
    with pytest.raises(ValueError, match="speed_setpoint_mps holds NaN or infinity"):
        physics.set_commands(zeros, np.array([np.inf, 1.0]))  # was flown at full thrust
    with pytest.raises(ValueError, match="xy_m holds NaN"):
        physics.set_poses(np.array([[np.nan, 1.0], [2.0, 3.0]]), zeros, np.ones(2))
    before = physics.model.body_pos[physics._nodes, :2].copy()
    with pytest.raises(ValueError, match=r"nodes_m has shape \(1, 2\); accepted: \(7, 2\)"):
        physics.place_scene(np.array([[5.0, 5.0]]), zeros)  # was broadcast to all 7 markers
    with pytest.raises(ValueError, match=r"current_mps has shape \(\)"):
        physics.place_scene(before, 0.3)  # was broadcast to both components
    np.testing.assert_array_equal(physics.model.body_pos[physics._nodes, :2], before)
    physics.step(2)  # still a working scene
    assert np.isfinite(physics.positions_m()).all()


def test_the_stepper_refuses_no_scene_and_scenes_of_different_sizes(physics):
    other = AUVPhysics.from_config(fixed_config(1, 7))
    stepper = Stepper()
    try:
        with pytest.raises(UsageError, match="no physics"):
            stepper.step([], 3)  # IndexError
        with pytest.raises(ValueError, match="scenes of different sizes"):
            stepper.step([physics, other], 3)
    finally:
        stepper.close()
        other.free()


def test_task_rngs_refuse_seeds_numpy_cannot_take():
    env = KinematicEnvironment(fixed_config(1, 7), seed=2**32 - 1)
    with pytest.raises(UsageError, match=r"seed=4294967296 is invalid.*4294967295 or None"):
        env.reseed(2**32)  # numpy's "Seed must be between 0 and 2**32 - 1"
    gym_env = gym.make(ENV_ID, backend="kinematic", n_auvs=1)
    with pytest.raises(ValueError, match="seed=4294967296 is invalid"):
        gym_env.reset(seed=2**32)


# ------------------------------------------------------------------ training configs
@pytest.mark.parametrize(
    ("build", "match"),
    [
        (lambda: PhaseConfig(timesteps=1.5), "timesteps=1.5 has the wrong type"),  # taken
        (lambda: PhaseConfig(node_range=(3,)), "node_range=.* list of 2 values"),  # unpack
        (lambda: TrainConfig(phases=None), "phases=None has the wrong type"),  # len(None)
        (lambda: TrainConfig(seed=1.5), "seed=1.5 has the wrong type"),  # taken
        (lambda: TrainConfig(net_arch=64), "net_arch=64 has the wrong type"),  # len(int)
        (lambda: TrainConfig(n_auvs=2.0), "n_auvs=2.0 has the wrong type"),  # slicing
        (lambda: TrainConfig(noise_models=("flat", "flat")), "each once"),  # cells doubled
        (lambda: MarlPhase(agent_steps=1.5), "agent_steps=1.5 has the wrong type"),
        (lambda: MarlConfig(n_auvs=5, n_max=5), "n_auvs=5 is invalid"),  # failed at an env
        (lambda: MarlConfig(env={"scenario": {"n_auvs": 3}}), "n_auvs=2 contradicts"),
    ],
)
def test_training_configs_built_in_code_are_checked_as_files_are(build, match):
    with pytest.raises(ConfigError, match=match):
        build()


def test_training_configs_built_in_code_take_lists_and_mappings_as_files_do():
    cfg = TrainConfig(phases=[{"backend": "kinematic", "timesteps": 5}], net_arch=[32])
    assert cfg.phases == (PhaseConfig("kinematic", 5),) and cfg.net_arch == (32,)


@pytest.mark.parametrize(
    ("build", "match"),
    [
        (lambda: ScenarioConfig(n_auvs=2.5), r"n_auvs=2.5 has the wrong type: accepted an integer"),
        (lambda: ScenarioConfig(area_m="big"), r"area_m='big' has the wrong type: accepted a list"),
        (lambda: MotionConfig(v_max_mps="4"), r"v_max_mps='4' was read as text"),
        (lambda: Config(motion=4), r"motion=4 has the wrong type: accepted a mapping"),
    ],
)
def test_config_sections_built_in_code_are_type_checked_as_files_are(build, match):
    with pytest.raises(ConfigError, match=match):
        build()


def test_config_sections_built_in_code_convert_lists_as_files_do():
    scenario = ScenarioConfig(area_m=[1000, 1200])
    assert scenario.area_m == (1000.0, 1200.0) and isinstance(scenario.area_m, tuple)
    assert Config(motion={"v_max_mps": 2.0}).motion == MotionConfig(v_max_mps=2.0)
