"""The `iout-mj` command line, run as a user would."""

import dataclasses
import json
import os
import re
import shlex
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from conftest import ROOT
from conftest import run_cli as run

from iout_mj.config import AcousticsConfig
from iout_mj.errors import PolicyError, UsageError
from iout_mj.schema import ConfigError
from iout_mj.world import acoustics


def test_link_budget_json():
    rows = json.loads(run("link-budget", "--distance", "10", "100", "500", "--json").stdout)
    assert [r["distance_m"] for r in rows] == [10, 100, 500]
    keys = {
        "distance_m",
        "harvest_power_w",
        "harvest_energy_j",
        "uplink_power_w",
        "uplink_energy_j",
    }
    cfg = AcousticsConfig()
    for r in rows:
        assert set(r) == keys
        assert r["harvest_energy_j"] == pytest.approx(
            float(acoustics.harvest_energy_j(r["distance_m"], cfg))
        )
        assert r["uplink_energy_j"] == pytest.approx(r["uplink_power_w"] * 25)
    assert rows[1]["harvest_energy_j"] == pytest.approx(3.281, abs=1e-3)


@pytest.mark.parametrize("bad", ["-5", "0", "far"])
def test_link_budget_rejects_bad_distances(bad):
    out = run("link-budget", "--distance", bad, check=False)
    assert out.returncode == 2
    assert "distance" in out.stderr and "accepted" in out.stderr


def test_link_budget_table_and_bad_config(tmp_path):
    assert "harvest J" in run("link-budget").stdout
    bad = tmp_path / "c.yaml"
    bad.write_text("acoustics:\n  p_tx_w: -1\n")
    out = run("link-budget", "--config", str(bad), check=False)
    assert out.returncode == 2 and "p_tx_w=-1.0 is invalid" in out.stderr


def test_validate_energy_json(tmp_path):
    result = json.loads(run("validate-energy", "--json", "--out", str(tmp_path)).stdout)
    assert len(result["steady"]) == 8
    assert all(abs(r["rel_error"]) <= 0.02 for r in result["steady"])
    assert {m["name"].split()[0] for m in result["maneuvers"]} >= {
        "accelerate",
        "90",
        "zig-zag",
        "slowdown",
        "mission",
    }
    by_name = {m["name"]: m for m in result["maneuvers"]}
    assert not by_name["90 deg turn at 2 m/s"]["commandable"]  # a 90 deg setpoint jump
    assert by_name["turn 25 deg per slot to 90"]["commandable"]
    for m in result["maneuvers"]:  # the arc flown is never shorter than the chord
        assert m["model_path_energy_j"] >= m["model_energy_j"] - 1e-6
    assert result["timestep"]["rel_change_quarter_dt"] < 0.01
    assert (tmp_path / "energy_validation.png").stat().st_size > 10_000


def test_mission_without_video(tmp_path):
    out = run("mission", "--slots", "3", "--no-video", "--out", str(tmp_path))
    summary = json.loads(out.stdout)
    assert summary["metrics"]["mission_slots"] == 3
    assert (tmp_path / "mission.json").exists()
    assert (tmp_path / "mission_trajectory.png").stat().st_size > 10_000


def test_unknown_policy_is_a_clear_error(tmp_path):
    out = run(
        "mission",
        "--policy",
        "genius",
        "--slots",
        "1",
        "--no-video",
        "--out",
        str(tmp_path),
        check=False,
    )
    assert out.returncode == 2 and "unknown policy 'genius'" in out.stderr


@pytest.mark.slow
def test_bench_quick_json_has_every_measure(tmp_path):
    r = json.loads(run("bench", "--quick", "--json").stdout)
    assert {"slot_vs_raw", "kinematic_steps_per_s", "ppo_fps_ratio", "subproc_scaling"} <= set(r)
    assert {"thread_scaling", "render_fps", "memory", "timestep_s", "substeps_per_slot"} <= set(r)
    (row,) = r["slot_vs_raw"].values()
    assert 0 < row["ratio"] < 2 and 0 < row["batch_8_ratio"] < 2
    assert r["substeps_per_slot"] * r["timestep_s"] == pytest.approx(25.0)
    assert r["kinematic_steps_per_s"]["N2_K13"] > r["kinematic_single_env_steps_per_s"]["N2_K13"]
    tokens = r["token_ppo_steps_per_s"]
    assert set(tokens) == {"kinematic", "mujoco", "trivial"} and min(tokens.values()) > 0
    assert r["token_ppo_ratio"] == pytest.approx(tokens["kinematic"] / tokens["trivial"])
    assert tokens["mujoco"] < tokens["kinematic"]  # the physics costs something
    channel = r["kinematic_realistic_channel_steps_per_s"]
    assert channel["N2_K13"] > channel["N2_K13_single_env"] > 0
    saved = tmp_path / "bench.json"
    saved.write_text(json.dumps(r))
    assert "N2_K13 under the realistic channel" in run("bench", "--from-json", saved).stdout


def test_bench_formats_the_saved_run_as_the_readme_table():
    saved_run = ROOT / "benchmarks" / "results-2cpu.json"
    out = run("bench", "--from-json", str(saved_run), "--markdown").stdout
    kin = json.loads(saved_run.read_text())["kinematic_steps_per_s"]["N2_K13"]
    assert (
        f"| kinematic_steps_per_s N2_K13, KinematicVecEnv of 64 [one env, gym.make] | {kin:,.0f}"
        in out
    )
    assert out in (ROOT / "README.md").read_text()  # the README shows this very run
    bad = run("bench", "--from-json", "missing.json", check=False)
    assert bad.returncode == 2 and "missing.json" in bad.stderr


def test_readme_shows_the_declared_observation():
    from iout_mj.mission import OBSERVATION_DOC

    assert OBSERVATION_DOC in (ROOT / "README.md").read_text()


def test_mission_accepts_any_k_with_the_fixed_layout(tmp_path):
    out = run("mission", "--nodes", "5", "--slots", "2", "--no-video", "--out", tmp_path)
    summary = json.loads(out.stdout)
    assert summary["n_nodes"] == 5 and len(summary["metrics"]["deliveries_per_node"]) == 5


def test_flags_apply_only_when_given_and_conflicts_are_errors(tmp_path):
    cfg = tmp_path / "scenario.yaml"
    nodes = [[100, 100], [300, 600], [600, 300], [500, 800], [900, 100]]
    cfg.write_text(json.dumps({"scenario": {"n_auvs": 3, "nodes_m": nodes}}))
    out = run("mission", "--config", cfg, "--slots", "2", "--no-video", "--out", tmp_path)
    summary = json.loads(out.stdout)
    assert (summary["n_auvs"], summary["n_nodes"]) == (3, 5)  # the file's, not 2 and 7
    bad = run("mission", "--config", cfg, "--nodes", "7", "--no-video", check=False)
    assert bad.returncode == 2 and "--nodes 7 contradicts" in bad.stderr and "sets 5" in bad.stderr


def test_train_overrides_only_what_is_given():
    from iout_mj.cli import build_parser
    from iout_mj.commands import train_overrides
    from iout_mj.training import TrainConfig

    cfg = TrainConfig.load(ROOT / "training/configs/ppo-general-n4-aoi-10m.yaml")
    assert cfg.torch_threads == 2
    parse = build_parser().parse_args
    assert train_overrides(cfg, parse(["train", "x.yaml"])) == cfg
    threads = train_overrides(cfg, parse(["train", "x.yaml", "--torch-threads", "1"]))
    assert threads == dataclasses.replace(cfg, torch_threads=1)


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (("mission", "--seed", "-1"), "accepted an integer >= 0"),
        (("evaluate", "--episodes", "0"), "accepted an integer >= 1"),
        (("train", "x.yaml", "--torch-threads", "0"), "accepted an integer >= 1"),
        (("mission", "--width", "8"), "accepted an integer from 16 to 1920"),
        (("figures", "--results", "x", "--label", "ppo"), "--label 'ppo': accepted POLICY=NAME"),
        (("figures", "--runs", "x", "--policies", "ppo"), "--policies need --results DIR"),
    ],
)
def test_bad_arguments_say_what_is_accepted(args, match):
    out = run(*args, check=False)
    assert out.returncode == 2 and match in out.stderr


def test_unwritable_output_fails_before_the_work(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    for args in (
        ("mission", "--no-video", "--out", blocker / "sub"),
        ("evaluate", "--episodes", "1", "--out", blocker / "sub"),
        ("validate-energy", "--out", blocker / "sub"),
    ):
        start = time.perf_counter()
        out = run(*args, check=False)
        assert out.returncode == 2 and "cannot write to" in out.stderr
        assert time.perf_counter() - start < 20


def test_a_current_that_once_diverged_the_physics_is_refused_before_the_mission(tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text("physics:\n  current_mps: [1.0e9, 0.0]\n")
    out = run(
        "mission", "--config", cfg, "--slots", "3", "--no-video", "--out", tmp_path, check=False
    )
    assert out.returncode == 2 and "current_mps" in out.stderr and "accepted" in out.stderr
    assert not (tmp_path / "mission.json").exists()


def test_a_diverged_mission_exits_3_with_the_error_once(capsys):
    from iout_mj.commands import DIVERGED, _diverged

    error = "physics diverged (MuJoCo reset the state)"
    assert _diverged({"metrics": {"valid": False, "error": error}}, "mission") == DIVERGED == 3
    assert capsys.readouterr().err == f"iout-mj mission: error: {error}\n"
    assert _diverged({"metrics": {"valid": True}}, "mission") == 0


def test_evaluate_skips_cells_a_policy_cannot_serve():
    out = run(
        *("evaluate", "--policy", "greedy", "ppo-n1-k7", "--n-auvs", "1", "--nodes", "3", "7"),
        *("--episodes", "1", "--backend", "kinematic", "--json"),
    )
    cells = {(r["policy"], r["n_nodes"]) for r in json.loads(out.stdout)}
    assert cells == {("greedy", 3), ("greedy", 7), ("ppo-n1-k7", 7)}
    assert "skipped ppo-n1-k7 at N=1, K=3" in out.stderr


def test_evaluate_flies_a_shipped_general_policy_for_every_n():
    out = run(
        *("evaluate", "--policy", "ppo-general", "--n-auvs", "1", "2", "3", "4", "--nodes", "3"),
        *("--layout", "random", "--episodes", "1", "--backend", "kinematic", "--json"),
    )
    rows = {r["n_auvs"]: r for r in json.loads(out.stdout)}
    assert set(rows) == {1, 2, 3, 4} and "skipped" not in out.stderr
    assert all(np.isfinite(r["mean_aoi_horizon"]) for r in rows.values())


def test_evaluate_flies_mappo_as_the_shipped_team_policy_for_each_n():
    out = run(
        *("evaluate", "--policy", "mappo", "greedy", "--n-auvs", "1", "2", "--nodes", "5"),
        *("--layout", "random", "--episodes", "1", "--backend", "kinematic", "--json"),
    )
    rows = {(r["policy"], r["n_auvs"]): r for r in json.loads(out.stdout)}
    assert set(rows) == {("mappo", 2), ("greedy", 1), ("greedy", 2)}
    assert np.isfinite(rows["mappo", 2]["mean_aoi_horizon"])
    assert "skipped mappo at N=1, K=5: unknown policy 'mappo-n1'" in out.stderr
    alone = run("evaluate", "--policy", "mappo", "--n-auvs", "1", "--nodes", "5", check=False)
    assert alone.returncode != 0 and "unknown policy 'mappo-n1'" in alone.stderr


def readme_commands():
    """Every `iout-mj ...` example of the README (code blocks and the command table)."""
    text = (ROOT / "README.md").read_text()
    found = re.findall(r"`iout-mj ([^`]+)`", text)
    found += re.findall(r"^\.venv/bin/iout-mj ([^#\n]+)", text, flags=re.M)
    return [shlex.split(c) for c in found if "--help" not in c]


def test_readme_examples_parse_and_the_cheap_ones_run(tmp_path):
    from iout_mj.cli import build_parser

    commands = readme_commands()
    assert len(commands) >= 15
    for argv in commands:
        build_parser().parse_args(argv)  # exits (SystemExit) on any unknown flag or value
    cheap = [c for c in commands if c[0] == "link-budget"]
    for argv in cheap:
        run(*argv)


HEAVY = ("mujoco", "dm_control", "torch", "stable_baselines3", "ray", "matplotlib")


def test_the_parser_imports_no_heavy_layer_and_shows_the_registries_names():
    probe = (
        "import sys, iout_mj.cli as cli; cli.build_parser().format_help(); "
        f"print(sorted(m for m in {HEAVY!r} + ('iout_mj.commands', 'iout_mj.envs') "
        "if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
    from iout_mj import cli
    from iout_mj.agents.registry import POLICIES

    assert tuple(POLICIES) == cli.BASELINES


def command_raising(monkeypatch, exc):
    from iout_mj import cli, commands

    def cmd(args):
        raise exc

    monkeypatch.setattr(commands, "cmd_link_budget", cmd)
    return cli.main


def test_a_bug_is_a_traceback_not_bad_input(monkeypatch):
    main = command_raising(monkeypatch, ValueError("a bug in the code, not in the input"))
    with pytest.raises(ValueError, match="a bug in the code"):
        main(["link-budget"])


@pytest.mark.parametrize(
    "exc", [ConfigError("bad key"), PolicyError("bad policy"), UsageError("bad flag")]
)
def test_the_projects_own_errors_are_bad_input(monkeypatch, capsys, exc):
    main = command_raising(monkeypatch, exc)
    assert main(["link-budget"]) == 2
    assert capsys.readouterr().err == f"iout-mj link-budget: error: {exc}\n"


def interrupt():
    raise KeyboardInterrupt


def interrupt_during_cleanup():
    try:
        raise KeyboardInterrupt
    except KeyboardInterrupt:
        raise RuntimeError("the video encoder was interrupted too") from None


@pytest.mark.parametrize("raise_it", [interrupt, interrupt_during_cleanup])
def test_ctrl_c_is_one_line_and_exit_130(monkeypatch, capsys, raise_it):
    from iout_mj import cli, commands

    def cmd(args):
        raise_it()

    monkeypatch.setattr(commands, "cmd_link_budget", cmd)
    monkeypatch.setattr(sys, "unraisablehook", sys.unraisablehook)  # restored after the test
    assert cli.main(["link-budget"]) == 130
    assert capsys.readouterr().err == "iout-mj link-budget: interrupted\n"


@pytest.mark.slow
def test_ctrl_c_ends_an_evaluation_and_its_workers_quietly(tmp_path):
    argv = ["evaluate", "--policy", "greedy", "--episodes", "20000", "--backend", "kinematic"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "iout_mj.cli", *argv, "--workers", "2", "--out", tmp_path],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        env={k: v for k, v in os.environ.items() if k != "TQDM_DISABLE"},  # the bar is the cue
    )
    # stderr read as it comes, character by character (the progress bar ends its updates with
    # a carriage return, not a newline): the bar says when the episodes run
    err_lines: list[str] = []
    reader = threading.Thread(
        target=lambda: err_lines.extend(iter(lambda: proc.stderr.read(1), ""))
    )
    reader.start()
    deadline = time.monotonic() + 120
    while not re.search(r"\| [1-9]\d*/\d+", "".join(err_lines)) and time.monotonic() < deadline:
        time.sleep(0.1)  # until the workers have finished an episode (the pool is up)
    running = proc.poll() is None
    os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal does: the whole group
    try:
        proc.wait(timeout=60)
    except subprocess.TimeoutExpired:  # a hang: say which processes of the group are left
        left = subprocess.run(
            ["ps", "-o", "pid,stat,etime,args", "-g", str(proc.pid)], capture_output=True, text=True
        ).stdout
        os.killpg(proc.pid, signal.SIGKILL)
        pytest.fail(f"no exit 60 s after Ctrl-C; left:\n{left}\n{''.join(err_lines)[-500:]}")
    reader.join(timeout=60)
    err = "".join(err_lines)
    assert running, f"the evaluation ended before the interrupt: {err[-500:]}"
    assert proc.returncode == 130, err
    assert "iout-mj evaluate: interrupted" in err and "Traceback" not in err


def test_a_busy_output_folder_is_refused_at_once(tmp_path):
    from iout_mj.runtime import output_lock

    with output_lock(tmp_path, "evaluate"):
        for args in (
            ("evaluate", "--policy", "greedy", "--episodes", "1", "--backend", "kinematic"),
            ("mission", "--no-video", "--slots", "1"),
            ("figures", "--results", tmp_path),
            ("train", ROOT / "training" / "configs" / "smoke.yaml"),
        ):
            out = run(*args, "--out", tmp_path, check=False)
            assert out.returncode == 2 and f"{tmp_path} is in use by iout-mj evaluate" in (
                out.stderr
            ), out.stderr
            assert not (tmp_path / "results.json").exists()
    run("mission", "--no-video", "--slots", "1", "--out", tmp_path)  # free again


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (("--policy", "greedy", "greedy"), "policy greedy given more than once"),
        (("--n-auvs", "1", "1"), "N 1 given more than once"),
        (("--workers", "1000"), "workers=1000 is invalid: accepted an integer from 1 to"),
    ],
)
def test_evaluate_refuses_repeated_cells_and_more_workers_than_cpus(args, match):
    out = run("evaluate", "--episodes", "1", "--backend", "kinematic", *args, check=False)
    assert out.returncode == 2 and match in out.stderr, out.stderr


def test_mission_slots_stop_early_only():
    out = run("mission", "--slots", "56", "--no-video", check=False)
    assert out.returncode == 2 and "accepted 1 to 55" in out.stderr


def test_frame_sizes_are_bounded_by_the_scenes_framebuffer():
    import xml.etree.ElementTree as ET

    from iout_mj.cli import MAX_FRAME_PX

    frame = ET.parse(ROOT / "assets" / "arena.xml").find("visual/global")
    assert (int(frame.get("offwidth")), int(frame.get("offheight"))) == MAX_FRAME_PX
    for args, match in (
        (("mission", "--width", "1921"), "accepted an integer from 16 to 1920"),
        (("render", "--height", "100000"), "accepted an integer from 16 to 1080"),
        (("render", "--fps", "0"), "accepted an integer from 1 to 240"),
    ):
        out = run(*args, check=False)
        assert out.returncode == 2 and match in out.stderr, out.stderr


def test_an_evaluation_of_more_than_max_episodes_is_refused_before_it_starts():
    from iout_mj.experiments.evaluate import MAX_EPISODES, evaluate

    start = time.perf_counter()
    with pytest.raises(UsageError, match=f"= {2 * MAX_EPISODES} episodes: accepted at most"):
        evaluate(["greedy", "planner"], [1], [7], MAX_EPISODES, 0, "kinematic", progress=False)
    assert time.perf_counter() - start < 10


def test_config_repeats_and_combines_files_in_order():
    """`--config A --config B`: B's keys override A's section by section (every command takes
    it; `config` shows the result)."""
    env = ROOT / "training" / "configs" / "env"
    realistic, wenz = env / "realistic-channel.yaml", env / "wenz.yaml"
    shown = run("config", "--config", realistic, "--config", wenz).stdout
    assert 'noise_model: "wenz"' in shown
    assert 'features: ["depth", "propagation", "packets", "interference", "fading"]' in shown
    swapped = run("config", "--config", wenz, "--config", realistic).stdout
    assert 'noise_model: "wenz"' in swapped  # the channel file does not set the noise
    bellhop = env / "realistic-channel-bellhop.yaml"
    budget = run("link-budget", "--config", realistic, "--config", bellhop).stdout
    assert "TL from the table realistic-channel-bellhop.npz" in budget
