"""Kill and resume: a training run SIGKILLed at any moment and resumed from its last checkpoint
ends bit for bit as the uninterrupted run (weights, optimizer, RNGs, normalisation, run state
and evaluation history), whether killed inside a phase, in the last rollout of a phase or
inside a checkpoint write; and the environments' state round-trips exactly."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml
from safetensors.torch import load_file

from iout_mj.agents.policy_format import FILES, NORMALIZATION, WEIGHTS, read_manifest
from iout_mj.config import Config
from iout_mj.envs import KinematicVecEnv, PhysicsVecEnv
from iout_mj.envs.scenario_vec_env import ScenarioVecEnv
from iout_mj.errors import PolicyError
from iout_mj.training import PhaseConfig, TrainConfig, train
from iout_mj.training.config import ImitationConfig

N_ENVS, N_STEPS = 4, 32
ROLLOUT = N_ENVS * N_STEPS
"""Steps of one rollout; the runs evaluate and save a checkpoint at every rollout start."""
PHASE = 4 * ROLLOUT
"""Steps of each phase: kinematic, then MuJoCo."""


def config() -> TrainConfig:
    return TrainConfig(
        name="kill",
        n_auvs=1,
        n_nodes=7,
        n_envs=N_ENVS,
        n_steps=N_STEPS,
        batch_size=64,
        n_epochs=2,
        net_arch=(16, 16),
        eval_every_steps=ROLLOUT,
        eval_episodes=1,
        phases=(PhaseConfig("kinematic", PHASE), PhaseConfig("mujoco", PHASE)),
    )


def general_config() -> TrainConfig:
    """A general (token) policy on 4 scenario cells, warm-started by DAgger."""
    return TrainConfig(
        name="kill-general",
        n_auvs=1,
        policy="tokens",
        node_range=(3, 4),
        width=8,
        n_envs=1,
        n_steps=N_STEPS,
        batch_size=64,
        n_epochs=1,
        eval_every_steps=ROLLOUT,
        eval_episodes=2,
        eval_node_range=(3, 5),  # held-out episodes on K = 3 and 5
        imitation=ImitationConfig(
            episodes=2, epochs=1, rounds=1, round_episodes=1, round_epochs=1, node_range=(3, 5)
        ),
        phases=(PhaseConfig("kinematic", PHASE), PhaseConfig("kinematic", 2 * ROLLOUT)),
        seed=1,  # PPO's seed (1) then differs from the first phase's environments' (1000)
    )


def _uninterrupted(root: Path, cfg: TrainConfig) -> tuple[Path, TrainConfig, Path]:
    """The config file, the config as the killed runs read it, and the uninterrupted run."""
    path = root / "config.yaml"
    path.write_text(yaml.safe_dump(cfg.to_dict()))
    cfg = TrainConfig.load(path)  # (its manifests then hold the numbers as the file has them)
    train(cfg, root / "whole", progress=False, parallel=False)
    return path, cfg, root / "whole"


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, TrainConfig, Path]:
    return _uninterrupted(tmp_path_factory.mktemp("resume"), config())


@pytest.fixture(scope="module")
def uninterrupted_general(
    tmp_path_factory: pytest.TempPathFactory,
) -> tuple[Path, TrainConfig, Path]:
    return _uninterrupted(tmp_path_factory.mktemp("resume-general"), general_config())


def _state(run: Path) -> dict:
    try:
        return json.loads((run / "state.json").read_text())
    except FileNotFoundError:
        return {}


def _last(run: Path) -> dict:
    """The manifest of last/, or {} where a kill left none in place."""
    try:
        return read_manifest(run / "last")
    except PolicyError:
        return {}


def train_and_kill(
    config_path: Path,
    run: Path,
    kill_when: Callable[[Path], bool],
    landed: Callable[[Path], bool],
    attempts: int = 3,
) -> None:
    """Train in a fresh interpreter and SIGKILL it the moment `kill_when(run)` holds; again,
    from scratch, where the run folder shows that the kill did not land where `landed` says
    (a loaded machine may react late)."""
    for _ in range(attempts):
        shutil.rmtree(run, ignore_errors=True)
        _kill(config_path, run, kill_when)
        if landed(run):
            return
    pytest.fail(f"the kill did not land where it should in {attempts} runs")


def _kill(config_path: Path, run: Path, kill_when: Callable[[Path], bool]) -> None:
    code = (
        "import sys; from pathlib import Path; from iout_mj.training import TrainConfig, train; "
        "train(TrainConfig.load(sys.argv[1]), Path(sys.argv[2]), progress=False, parallel=False)"
    )
    with open(run.with_suffix(".stderr"), "w") as stderr:
        proc = subprocess.Popen(
            [sys.executable, "-c", code, str(config_path), str(run)],
            stdout=subprocess.DEVNULL,
            stderr=stderr,
        )
        deadline = time.monotonic() + 300
        while proc.poll() is None and time.monotonic() < deadline:
            if kill_when(run):
                proc.send_signal(signal.SIGKILL)
                break
            time.sleep(0.0002)
        proc.wait()
    assert proc.returncode == -signal.SIGKILL, (
        f"the run ended (exit {proc.returncode}) before it could be killed: "
        + run.with_suffix(".stderr").read_text()[-2000:]
    )


def assert_same_checkpoint(folder: Path, expected: Path) -> None:
    """Every tensor, the normalisation, the manifest, and then every byte, equal."""
    got, want = load_file(str(folder / WEIGHTS)), load_file(str(expected / WEIGHTS))
    assert set(got) == set(want)
    for key in want:  # policy.*, optimizer.*, rng.*
        assert got[key].dtype == want[key].dtype and torch.equal(got[key], want[key]), key
    for name in (NORMALIZATION, "policy.json"):
        assert json.loads((folder / name).read_text()) == json.loads((expected / name).read_text())
    for name in FILES:
        assert (folder / name).read_bytes() == (expected / name).read_bytes(), name


def resume_and_compare(cfg: TrainConfig, run: Path, whole: Path) -> None:
    resumed = train(cfg, run, resume=True, progress=False, parallel=False)
    assert resumed.num_timesteps == cfg.total_timesteps and resumed.phase == 2
    assert _state(run) == _state(whole)  # the evaluation history and best score, exactly
    for folder in ("last", "best"):
        assert_same_checkpoint(run / folder, whole / folder)
    assert sorted(p.name for p in run.iterdir()) == sorted(p.name for p in whole.iterdir())


@pytest.mark.slow
def test_killed_in_the_last_rollout_of_a_phase(uninterrupted, tmp_path):
    """Killed after the checkpoint at the start of the first phase's last rollout: the resumed
    run finishes that rollout on the same episodes, then starts the next phase as the
    uninterrupted run did."""
    path, cfg, whole = uninterrupted
    run = tmp_path / "run"

    def landed(r: Path) -> bool:  # and the running episodes are in that checkpoint
        last = _last(r)
        return last.get("num_timesteps") == PHASE - ROLLOUT and last.get("live") is not None

    train_and_kill(path, run, lambda r: _state(r).get("num_timesteps") == PHASE - ROLLOUT, landed)
    resume_and_compare(cfg, run, whole)


@pytest.mark.slow
def test_killed_in_the_middle_of_a_phase(uninterrupted, tmp_path):
    """Killed in the middle of a MuJoCo rollout, mid-episode: the scenes, energy meters,
    episodes, RNG streams and normalisation continue as if nothing happened."""
    path, cfg, whole = uninterrupted
    run = tmp_path / "run"

    def mid_rollout(r: Path) -> bool:  # 0.1 s after the checkpoint (a rollout takes ~0.5 s)
        state = _state(r)
        return (
            state.get("num_timesteps") == PHASE + ROLLOUT
            and time.time() - (r / "state.json").stat().st_mtime > 0.1
        )

    def landed(r: Path) -> bool:
        last = _last(r)
        return last.get("num_timesteps") == PHASE + ROLLOUT and last.get("env_phase") == 1

    train_and_kill(path, run, mid_rollout, landed)
    resume_and_compare(cfg, run, whole)


@pytest.mark.slow
def test_killed_inside_a_checkpoint_write(uninterrupted, tmp_path):
    """Killed while last/ is being replaced (last.tmp or last.old on disk): --resume keeps
    the complete checkpoint, old or new, and still ends as the uninterrupted run."""
    path, cfg, whole = uninterrupted
    run = tmp_path / "run"

    def writing(r: Path) -> bool:
        return (r / "state.json").exists() and any(
            os.path.lexists(r / name) for name in ("last.tmp", "last.old")
        )

    def landed(r: Path) -> bool:  # the process is dead: what is on disk is what it left
        return any(os.path.lexists(r / name) for name in ("last.tmp", "last.old"))

    train_and_kill(path, run, writing, landed)
    resume_and_compare(cfg, run, whole)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("steps", "live"),
    [(0, False), (2 * ROLLOUT, True)],
    ids=["after-the-warm-start", "mid-phase"],
)
def test_a_general_policy_killed_and_resumed(uninterrupted_general, tmp_path, steps, live):
    """Token policy on scenario cells: killed after the checkpoint of the DAgger warm start
    (the environments not started yet), or mid-phase (every cell's episodes and streams
    running)."""
    path, cfg, whole = uninterrupted_general
    run = tmp_path / "run"

    def landed(r: Path) -> bool:
        last = _last(r)
        return last.get("num_timesteps") == steps and (last.get("live") is not None) == live

    train_and_kill(path, run, lambda r: _state(r).get("num_timesteps") == steps, landed)
    resume_and_compare(cfg, run, whole)


# ------------------------------------------------------------------ the environments' state
def _actions(venv, rng: np.random.RandomState) -> np.ndarray:
    nvec = venv.action_space.nvec.reshape(-1, 4).copy()
    nvec[:, 2:] = 3  # node indices valid in every cell (K >= 3)
    return rng.randint(nvec.reshape(-1), size=(venv.num_envs, nvec.size))


@pytest.mark.parametrize(
    "make",
    [
        lambda seed: KinematicVecEnv(3, n_auvs=2, n_nodes=7, seed=seed),
        lambda seed: PhysicsVecEnv(2, n_auvs=1, n_nodes=7, seed=seed),
        lambda seed: ScenarioVecEnv([(3, Config()), (4, Config())], 2, "kinematic", seed),
    ],
    ids=["kinematic", "mujoco", "scenario-cells"],
)
def test_env_state_round_trips_exactly(make):
    """A vector env loaded with another's state steps exactly as it does, across episode
    ends (new layouts, currents and jitter drawn from the restored streams)."""
    a, b = make(1), make(2)
    a.reset()
    b.reset()
    rng = np.random.RandomState(0)
    for _ in range(30):
        a.step(_actions(a, rng))
    b.load_state_arrays(a.state_arrays())
    for t in range(60):  # an episode is 55 slots
        actions = _actions(a, rng)
        (obs_a, rew_a, done_a, _), (obs_b, rew_b, done_b, _) = a.step(actions), b.step(actions)
        assert np.array_equal(obs_a, obs_b) and np.array_equal(rew_a, rew_b), t
        assert np.array_equal(done_a, done_b), t
    sa, sb = a.state_arrays(), b.state_arrays()
    assert sa.keys() == sb.keys()
    for key in sa:
        assert np.array_equal(sa[key], sb[key]), key


def test_env_state_of_another_env_is_refused():
    small, large = KinematicVecEnv(2, n_auvs=1, n_nodes=7), KinematicVecEnv(3, n_auvs=1, n_nodes=7)
    with pytest.raises(ValueError, match=r"state\.positions_m is float64\[3, 1, 2\]; accepted"):
        small.load_state_arrays(large.state_arrays())
    arrays = small.state_arrays()
    del arrays["0.state.slot"]
    with pytest.raises(ValueError, match=r"\['state.slot'\] unlike this batch: accepted exactly"):
        small.load_state_arrays(arrays)
    with pytest.raises(ValueError, match=r"'9.state.slot'.*index below 1"):
        small.load_state_arrays({**small.state_arrays(), "9.state.slot": np.zeros(2)})
