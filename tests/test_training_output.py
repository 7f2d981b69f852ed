"""What a training run shows its researcher: a progress bar through the imitation and each
phase, a console line per held-out evaluation, a summary naming the best checkpoint, and a
TensorBoard log with the config, the hyperparameters, phase markers and one step axis across
a crash and `--resume`."""

import errno
import json
import os
import re
import shutil
import time
from pathlib import Path
from typing import Any

import pytest
import yaml
from conftest import tiny_training
from tensorboard.backend.event_processing import plugin_event_accumulator
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
from tensorboard.plugins.hparams import plugin_data_pb2
from tensorboard.util import tensor_util

from iout_mj.agents import policy_format
from iout_mj.agents.policy_format import read_manifest
from iout_mj.errors import CheckpointError
from iout_mj.training import PhaseConfig, TrainConfig, train
from iout_mj.training.config import ImitationConfig
from iout_mj.training.trainer import TENSORBOARD_DIR, run_summary, selection_score

pytestmark = pytest.mark.slow

ROLLOUT = 2 * 64
"""Steps of one rollout (2 environments x 64 steps); an evaluation every rollout."""


def config() -> TrainConfig:
    phases = (PhaseConfig("kinematic", 2 * ROLLOUT), PhaseConfig("kinematic", 2 * ROLLOUT))
    return tiny_training(name="out", net_arch=(16, 16), eval_every_steps=ROLLOUT, phases=phases)


def scalars(run: Path) -> dict[str, list[tuple[int, float]]]:
    """The run's scalars as TensorBoard's EventAccumulator reads its event files."""
    acc = EventAccumulator(str(run / TENSORBOARD_DIR), size_guidance={"scalars": 0})
    acc.Reload()
    return {t: [(e.step, e.value) for e in acc.Scalars(t)] for t in acc.Tags()["scalars"]}


def tensors(run: Path) -> dict[str, list[tuple[int, Any]]]:
    """Every series of the run (scalars, texts) as the TensorBoard server's accumulator reads
    them (`plugin_event_accumulator`: texts are series too)."""
    acc = plugin_event_accumulator.EventAccumulator(
        str(run / TENSORBOARD_DIR), size_guidance={"tensors": 0}
    )
    acc.Reload()
    return {
        t.removesuffix("/text_summary"): [
            (e.step, tensor_util.make_ndarray(e.tensor_proto).item()) for e in acc.Tensors(t)
        ]
        for t in acc.Tags()["tensors"]
        if not t.startswith("_hparams_/")  # (the hparams view's metadata: no values)
    }


def texts(run: Path) -> dict[str, list[tuple[int, str]]]:
    return {
        t: [(s, v.decode()) for s, v in series]
        for t, series in tensors(run).items()
        if series and isinstance(series[0][1], bytes)
    }


REPRODUCED = ("eval/", "reward/", "episode/", "train/")
"""Tags whose values a resumed run reproduces exactly (time/ is wall time; rollout/ is SB3's
window of recent episodes, which a checkpoint does not hold)."""


def assert_one_step_axis(run: Path, whole: Path) -> None:
    """Every tag's steps strictly increase, and the reproduced tags hold the uninterrupted
    run's steps and values."""
    for read in (scalars, tensors):
        got, want = read(run), read(whole)
        for tag, points in got.items():
            steps = [s for s, _ in points]
            assert steps == sorted(set(steps)), (read.__name__, tag, steps)
        for tag in (t for t in want if t.startswith((*REPRODUCED, "run/phase"))):
            assert got[tag] == want[tag], (read.__name__, tag)


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str, dict]:
    """A run with its console output (stdout) and its summary."""
    run = tmp_path_factory.mktemp("output") / "run"
    capture = run.with_suffix(".stdout")
    with open(capture, "w") as stdout, pytest.MonkeyPatch.context() as mp:
        mp.setattr("sys.stdout", stdout)
        state = train(config(), run, parallel=False)
    return run, capture.read_text(), run_summary(config(), run, state)


def test_each_evaluation_is_printed_as_it_happens(uninterrupted):
    run, stdout, _ = uninterrupted
    history = json.loads((run / "state.json").read_text())["history"]
    lines = [line for line in stdout.splitlines() if line.startswith("eval ")]
    assert len(lines) == len(history) == 4  # every rollout, the phase ends included
    best = -1e300
    for line, entry in zip(lines, history, strict=True):
        phase = f"phase {entry['phase']}/2 kinematic"
        assert f"{entry['num_timesteps']:,} steps  {phase}" in line
        assert f"return {entry['return']:9.2f}" in line
        assert f"mean AoI over T_max {entry['mean_aoi_horizon']:7.2f} slots" in line
        assert f"docking {entry['docking_rate']:4.0%}  Jain {entry['jain']:.3f}" in line
        assert line.endswith("new best") == (selection_score(entry) > best)
        best = max(best, selection_score(entry))
    assert [h["phase"] for h in history] == [1, 1, 2, 2]  # the phase of the model evaluated


def test_the_summary_names_the_best_checkpoint_and_the_last(uninterrupted):
    run, _, summary = uninterrupted
    assert summary["phases_done"] == "2 of 2" and summary["num_timesteps"] == 4 * ROLLOUT
    for folder in ("best", "last"):
        kept = read_manifest(run / folder)["eval"]  # what the checkpoint itself was selected on
        named = summary[folder]
        assert named["checkpoint"] == str(run / folder)
        assert named["num_timesteps"] == kept["num_timesteps"]
        assert named["phase"] == f"{kept['phase']} of 2 (kinematic)"
        assert named["eval"] == {k: v for k, v in kept.items() if k in named["eval"]}
        assert set(named["eval"]) >= {"return", "mean_aoi_horizon", "docking_rate", "jain"}
    assert summary["last"]["num_timesteps"] == 4 * ROLLOUT
    assert summary["last"]["phase"] == "2 of 2 (kinematic)"


def test_tensorboard_holds_the_config_hyperparameters_and_phase_markers(uninterrupted):
    run, _, _ = uninterrupted
    logs = texts(run)
    (step, config_text), *_ = logs["run/config"]
    assert step == 0
    assert yaml.safe_load(re.sub(r"^    ", "", config_text, flags=re.M)) == config().to_dict()
    assert "| n_steps | 64 |" in logs["run/hyperparameters"][0][1]
    assert [(s, text.split(":")[0]) for s, text in logs["run/phase"]] == [
        (ROLLOUT, "phase 1/2 kinematic"),  # written with the phase's first rollout
        (3 * ROLLOUT, "phase 2/2 kinematic"),
    ]
    phase = scalars(run)["train/phase"]
    assert phase == [(ROLLOUT, 1), (2 * ROLLOUT, 1), (3 * ROLLOUT, 2), (4 * ROLLOUT, 2)]
    assert [s for s, _ in scalars(run)["eval/mean_aoi_horizon"]] == [
        ROLLOUT * k for k in (1, 2, 3, 4)
    ]
    acc = plugin_event_accumulator.EventAccumulator(str(run / TENSORBOARD_DIR))
    acc.Reload()
    hparams = plugin_data_pb2.HParamsPluginData.FromString(
        acc.PluginTagToContent("hparams")["_hparams_/session_start_info"]
    ).session_start_info.hparams
    assert hparams["n_steps"].number_value == 64 and hparams["gamma"].number_value == 0.99
    assert hparams["phases"].string_value == "kinematic 256, kinematic 256"


def test_a_run_resumed_after_a_crash_continues_one_step_axis(uninterrupted, tmp_path, capsys):
    """A disk fault stops the run in its third checkpoint, after that evaluation was logged and
    while last/ still holds the second: the resumed run's log hides what the crashed one
    logged after that checkpoint, and reads as the uninterrupted run's."""
    whole, _, _ = uninterrupted
    run = tmp_path / "run"
    real, writes = policy_format.save_file, []

    def disk_full_at_the_third_last(tensors, path):
        if path.parent.name == "last.tmp":
            writes.append(path)
            if len(writes) == 3:
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        real(tensors, path)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(policy_format, "save_file", disk_full_at_the_third_last)
        with pytest.raises(CheckpointError, match="No space left"):
            train(config(), run, progress=False, parallel=False)
    assert read_manifest(run / "last")["num_timesteps"] == 2 * ROLLOUT
    crashed = scalars(run)["eval/mean_aoi_horizon"]
    assert [s for s, _ in crashed] == [ROLLOUT, 2 * ROLLOUT, 3 * ROLLOUT]  # beyond last/

    train(config(), run, resume=True, progress=False, parallel=False)
    assert capsys.readouterr().out == ""  # quiet without progress
    assert len(list((run / TENSORBOARD_DIR).iterdir())) == 2  # the crashed and the resumed
    assert_one_step_axis(run, whole)
    logs = texts(run)
    assert [s for s, _ in logs["run/config"]] == [0]
    assert [s for s, _ in logs["run/phase"]] == [ROLLOUT, 3 * ROLLOUT]
    assert logs["run/resumed"] == [(3 * ROLLOUT, f"resumed at step {2 * ROLLOUT:,}")]


def test_overwrite_starts_a_fresh_log(uninterrupted, tmp_path):
    whole, _, _ = uninterrupted
    run = tmp_path / "run"
    shutil.copytree(whole, run)
    train(config(), run, progress=False, parallel=False, overwrite=True)
    assert len(list((run / TENSORBOARD_DIR).iterdir())) == 1
    assert_one_step_axis(run, whole)


def test_the_imitation_shows_its_progress(tmp_path, capsys):
    """The DAgger warm start: a bar of the episodes flown with the round and the fitting epoch
    beside it and a line per round, before the step bar of the PPO phase starts."""
    cfg = TrainConfig(
        name="dagger",
        n_auvs=1,
        policy="tokens",
        node_range=(3, 3),
        noise_models=("flat",),
        width=8,
        n_envs=2,
        n_steps=32,
        batch_size=64,
        n_epochs=1,
        eval_every_steps=10**6,
        eval_episodes=1,
        imitation=ImitationConfig(episodes=2, epochs=2, rounds=1, round_episodes=1, round_epochs=1),
        phases=(PhaseConfig("kinematic", 64),),
    )
    train(cfg, tmp_path / "run", parallel=False)
    out, err = capsys.readouterr()
    assert re.findall(r"imitation round (\d)/1: [\d,]+ states", out) == ["0", "1"]
    assert "3/3 [" in err  # the planner's 2 episodes, then the round's 1
    assert "round 0/1: fitting, epoch 2/2" in err and "round 1/1: the policy flies" in err
    assert err.index("dagger imitation") < err.index("dagger phase 1/1 kinematic")
    assert out.index("imitation round 1/1") < out.index("eval ")
    imitation = texts(tmp_path / "run")["run/imitation"]
    assert imitation[0][0] == 0 and "imitation round 1/1" in imitation[0][1]


def test_a_restarted_log_sorts_after_the_event_files_already_there(tmp_path):
    """TensorBoard reads event files in name order: a (re)started run's file must come after
    one written this very second by another host or process whose name sorts later."""
    from iout_mj.training.logs import run_logger

    earlier = tmp_path / f"events.out.tfevents.{int(time.time()):010d}.zzzz.99999.9"
    earlier.write_bytes(b"")
    run_logger(tmp_path, 5).close()
    names = sorted(f.name for f in tmp_path.glob("events.out.tfevents.*"))
    assert len(names) == 2 and names[0] == earlier.name
