"""PPO end to end: a short run on both backends, save, reload, predict, resume, refusal."""

import json
import os
import signal
import subprocess
import sys
import time

import gymnasium as gym
import pytest
import torch
import yaml
from conftest import ROOT, tiny_training
from safetensors.torch import load_file
from test_training_output import assert_one_step_axis

from iout_mj.agents import policy_format
from iout_mj.agents.policies import SHIPPED_DIR, load_policy, shipped_policies
from iout_mj.agents.policy_format import read_manifest
from iout_mj.agents.rollout import run_episode
from iout_mj.config import Config
from iout_mj.envs import ENV_ID
from iout_mj.mission.stats import episode_summary
from iout_mj.schema import ConfigError
from iout_mj.training import HELD_OUT_SEED, PhaseConfig, TrainConfig, train
from iout_mj.training.checkpoints import CheckpointError

pytestmark = pytest.mark.slow


def small(**kw):
    phases = (PhaseConfig("kinematic", 128), PhaseConfig("mujoco", 128))
    return tiny_training(**{"phases": phases, **kw})


def test_short_run_saves_reloads_predicts_and_resumes(tmp_path):
    cfg = small()
    state = train(cfg, tmp_path, progress=False, parallel=False)
    assert state.num_timesteps == 256 and state.phase == 2
    assert [h["backend"] for h in state.history][-1] == "mujoco"
    for folder in ("last", "best"):
        assert {p.name for p in (tmp_path / folder).iterdir()} == {
            "policy.json",
            "policy.json.sha256",
            "weights.safetensors",
            "normalization.json",
        }
    env = gym.make(ENV_ID, backend="mujoco", n_auvs=1, n_nodes=7)
    policy = load_policy(str(tmp_path / "last"), env)
    obs, _ = env.reset(seed=3)
    assert env.action_space.contains(policy(env, obs))
    # the saved checkpoint flies the held-out episode exactly as its evaluation recorded
    replay = episode_summary(run_episode(env, policy, HELD_OUT_SEED))
    last = state.history[-1]
    assert {k: last[k] for k in replay} == pytest.approx(replay)

    # resume: a longer schedule with the same config is refused; the same config continues
    with pytest.raises(ConfigError, match="different config"):
        train(
            small(phases=(PhaseConfig("kinematic", 128), PhaseConfig("mujoco", 512))),
            tmp_path,
            resume=True,
            progress=False,
            parallel=False,
        )
    with pytest.raises(CheckpointError, match=r"--resume.*--overwrite"):
        train(cfg, tmp_path, progress=False, parallel=False)
    resumed = train(cfg, tmp_path, resume=True, progress=False, parallel=False)
    assert resumed.num_timesteps == 256 and len(resumed.history) == len(state.history)
    again = train(cfg, tmp_path, progress=False, parallel=False, overwrite=True)
    assert again.history == state.history  # a fresh run of the same config and seed


def weights(folder):
    return load_file(str(folder / "weights.safetensors"))


def test_killed_and_resumed_run_ends_with_the_uninterrupted_weights(tmp_path, cli):
    """SIGKILL in the second phase; --resume continues from the end of the first phase and
    ends with the same step count and, bit for bit, the same weights, and its TensorBoard log
    reads as the uninterrupted run's (one step axis: what the killed run logged after its
    checkpoint is hidden)."""
    config = tmp_path / "k.yaml"
    cfg = small(
        n_envs=4,
        phases=(PhaseConfig("kinematic", 512), PhaseConfig("kinematic", 4096)),
        eval_every_steps=10**9,
        eval_episodes=1,
    )
    config.write_text(yaml.safe_dump(cfg.to_dict()))
    cli("train", config, "--out", tmp_path / "whole")
    run = tmp_path / "killed"
    proc = subprocess.Popen(
        [sys.executable, "-m", "iout_mj.cli", "train", config, "--out", run],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.time() + 120
    while time.time() < deadline and proc.poll() is None:
        state = run / "state.json"
        if state.is_file() and json.loads(state.read_text() or "{}").get("phase") == 1:
            proc.send_signal(signal.SIGKILL)
            break
        time.sleep(0.02)
    proc.wait()
    assert proc.returncode == -signal.SIGKILL, "the run ended before it could be killed"
    assert (
        not (run / "state.json").is_file()
        or json.loads((run / "state.json").read_text())["phase"] == 1
    )
    cli("train", config, "--out", run, "--resume")
    whole, resumed = weights(tmp_path / "whole" / "last"), weights(run / "last")
    assert set(whole) == set(resumed)
    for key in whole:
        if key.startswith(("policy.", "optimizer.")):
            assert torch.equal(whole[key], resumed[key]), key
    final = json.loads((run / "state.json").read_text())
    assert (
        final["num_timesteps"]
        == 512 + 4096
        == json.loads((tmp_path / "whole" / "state.json").read_text())["num_timesteps"]
    )
    assert_one_step_axis(run, tmp_path / "whole")


def test_policy_for_other_scenario_is_refused(tmp_path):
    train(small(phases=(PhaseConfig("kinematic", 64),)), tmp_path, progress=False, parallel=False)
    env = gym.make(ENV_ID, backend="kinematic", n_auvs=2, n_nodes=7)
    with pytest.raises(ValueError, match=r"trained for N=1, K=7.*this env has N=2, K=7"):
        load_policy(str(tmp_path / "last"), env)


def test_train_cli_rejects_bad_configs(tmp_path, cli):
    bad = tmp_path / "bad.yaml"
    bad.write_text("n_envs: 2\nn_steps: 10\nbatch_size: 7\n")
    out = cli("train", bad, "--out", tmp_path / "r", check=False)
    assert out.returncode == 2 and "batch_size=7 must divide" in out.stderr
    bad.write_text("learning_rat: 0.1\n")
    out = cli("train", bad, check=False)
    assert out.returncode == 2 and "unknown key" in out.stderr


def test_shipped_policies_load_and_refuse_other_scenarios():
    shipped = shipped_policies()
    assert "ppo-n1-k7" in shipped and all(
        (SHIPPED_DIR / n / "policy.json").is_file() for n in shipped
    )
    for name in (s for s in shipped if s.endswith("-k7")):  # the specialists (general: elsewhere)
        n = int(name.split("-")[1][1:])
        env = gym.make(ENV_ID, backend="kinematic", n_auvs=n, n_nodes=7)
        policy = load_policy(name, env)
        obs, _ = env.reset(seed=0)
        assert env.action_space.contains(policy(env, obs))
        other = gym.make(ENV_ID, backend="kinematic", n_auvs=n, n_nodes=13)
        with pytest.raises(ValueError, match="trained for"):
            load_policy(name, other)


@pytest.mark.parametrize(("errno", "text"), [(28, "No space left"), (30, "Read-only")])
def test_disk_faults_give_one_clear_error_and_keep_the_last_checkpoint(
    tmp_path, monkeypatch, errno, text
):
    cfg = small(phases=(PhaseConfig("kinematic", 128), PhaseConfig("kinematic", 128)))
    calls = {"n": 0}
    real = policy_format.save_file

    def failing(tensors, path):
        calls["n"] += 1
        if calls["n"] > 2:  # best/ and last/ of the first phase are written
            raise OSError(errno, os.strerror(errno))
        real(tensors, path)

    monkeypatch.setattr(policy_format, "save_file", failing)
    with pytest.raises(CheckpointError, match=f"cannot write checkpoint .*{text}"):
        train(cfg, tmp_path, progress=False, parallel=False)
    assert not any(p.name.endswith(".tmp") for p in tmp_path.iterdir())
    kept = read_manifest(tmp_path / "last")  # complete, checksums verified
    assert kept["run_state"]["phase"] == 1


def test_a_kill_between_the_renames_is_recovered_and_state_json_is_not_needed(tmp_path):
    cfg = small(phases=(PhaseConfig("kinematic", 128), PhaseConfig("kinematic", 128)))
    train(cfg, tmp_path, progress=False, parallel=False)
    (tmp_path / "last").rename(tmp_path / "last.tmp")  # killed before the final rename
    (tmp_path / "state.json").write_text('{"phase": 1, "num_ti')  # and a torn copy
    resumed = train(cfg, tmp_path, resume=True, progress=False, parallel=False)
    assert resumed.num_timesteps == 256 and (tmp_path / "last" / "policy.json").is_file()


def test_the_training_config_carries_the_env_config(tmp_path):
    env = Config.from_dict({"acoustics": {"noise_model": "wenz"}})
    cfg = small(phases=(PhaseConfig("kinematic", 64),), env=env)
    train(cfg, tmp_path, progress=False, parallel=False)
    manifest = read_manifest(tmp_path / "last")
    assert manifest["env_config"]["acoustics"]["noise_model"] == "wenz"
    assert TrainConfig.load(tmp_path / "config.yaml") == cfg  # the env config round-trips


def test_rl_zoo3_trains_with_the_shipped_hyperparameters(tmp_path):
    """rl-zoo3 finds the env through --gym-packages and the project's hyperparameter file."""
    out = subprocess.run(
        [
            *(sys.executable, "-m", "rl_zoo3.train", "--algo", "ppo"),
            *("--env", "iout_mj/MultiAUV-v0", "--gym-packages", "iout_mj"),
            *("-conf", str(ROOT / "training" / "configs" / "rl-zoo3-ppo.yml")),
            *("-n", "4096", "--eval-freq", "-1", "--log-folder", str(tmp_path)),
        ],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert list(tmp_path.glob("ppo/iout_mj-MultiAUV-v0_1/*.zip"))


def test_ppo_trains_on_the_warp_backend_through_the_training_config(tmp_path):
    pytest.importorskip("mujoco_warp")
    cfg = small(phases=(PhaseConfig("warp", 16),), n_steps=8, batch_size=16, eval_every_steps=16)
    state = train(cfg, tmp_path / "run", progress=False)
    assert state.num_timesteps == 16 and state.history[-1]["backend"] == "warp"
    assert (tmp_path / "run" / "best" / "policy.json").is_file()
