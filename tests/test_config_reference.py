"""The documented config: the reference made from the config's own checks, `config --dump`
as a file to start from, `list`, `--version` and `--quiet`."""

import json
import subprocess
import sys

import yaml
from conftest import ROOT

from iout_mj import config_reference
from iout_mj.agents.registry import POLICIES
from iout_mj.backends.registry import BACKENDS
from iout_mj.config import Config
from iout_mj.scenarios import SCENARIOS


def test_docs_config_md_is_the_generated_reference():
    assert (ROOT / "docs" / "config.md").read_text() == config_reference.markdown(), (
        "regenerate it: iout-mj config --markdown > docs/config.md"
    )


def test_every_field_is_documented_with_what_it_accepts():
    rows = config_reference.fields()
    assert len(rows) > 60
    assert all(r.accepted for r in rows), [r.name for r in rows if not r.accepted]
    by_name = {(r.section, r.name): r for r in rows}
    assert by_name["motion", "v_max_mps"].unit == "m/s"
    assert "[0.5, 20]" in by_name["motion", "v_max_mps"].accepted[0]
    assert by_name["reward.weights", "aoi"].default == -0.1


def test_the_dump_is_a_config_file_that_loads_back(tmp_path, cli):
    out = cli("config", "--dump")
    path = tmp_path / "dump.yaml"
    path.write_text(out.stdout)
    assert Config.load(path) == Config()
    mine = ROOT / "training" / "configs" / "env" / "my-scenario.yaml"
    path.write_text(cli("config", "--config", mine).stdout)
    assert Config.load(path) == Config.load(mine)
    assert "# m/s; a number in [0.5, 20]" in out.stdout  # units and ranges as comments
    assert yaml.safe_load(out.stdout)["scenario"]["horizon_slots"] == 55


def test_list_names_what_the_registries_hold(cli):
    listing = json.loads(cli("list", "--json").stdout)
    assert set(listing["backends"]) == set(BACKENDS)
    assert set(POLICIES) <= set(listing["policies"]) and "ppo-general" in listing["policies"]
    assert set(listing["scenarios"]) == set(SCENARIOS)
    assert {"paper", "random", "custom"} == set(listing["layouts"])


def test_version_and_quiet(cli):
    version = cli("--version").stdout.strip()
    assert version.startswith("iout-mj ") and version.split()[1][0].isdigit()
    args = ("evaluate", "--policy", "greedy", "--n-auvs", "1", "--episodes", "2", "--backend")
    loud = cli(*args, "kinematic", "--workers", "1")
    quiet = cli("--quiet", *args, "kinematic", "--workers", "1")
    assert "episodes" in loud.stderr and "episodes" not in quiet.stderr
    assert quiet.stdout == loud.stdout  # the same table


def test_quiet_leaves_the_callers_environment_as_it_was(monkeypatch, capsys):
    import os

    from iout_mj.cli import main

    monkeypatch.delenv("TQDM_DISABLE", raising=False)
    assert main(["--quiet", "list"]) == 0
    assert "TQDM_DISABLE" not in os.environ  # the subprocesses a caller starts later show bars
    monkeypatch.setenv("TQDM_DISABLE", "0")
    assert main(["--quiet", "list"]) == 0 and os.environ["TQDM_DISABLE"] == "0"


def test_top_level_help_names_every_command():
    out = subprocess.run(
        [sys.executable, "-m", "iout_mj.cli", "--help"], capture_output=True, text=True, check=True
    ).stdout
    for command in ("link-budget", "validate-energy", "mission", "render", "evaluate", "compare"):
        assert command in out
    for command in ("figures", "train", "export", "sweep", "bench", "config", "list"):
        assert command in out


def test_every_training_key_is_documented_with_what_it_accepts():
    from dataclasses import fields

    from iout_mj.training.config import TrainConfig
    from iout_mj.training.marl import MarlConfig

    rows = config_reference.training_fields()
    assert all(r.accepted for r in rows), [r.name for r in rows if not r.accepted]
    by_name = {(r.section, r.name): r for r in rows}
    sections = {"env", "phases", "imitation"}
    for section, cls in (("train", TrainConfig), ("train-marl", MarlConfig)):
        keys = {name for s, name in by_name if s == section}
        assert keys == {f.name for f in fields(cls)} - sections
    assert by_name["train", "n_envs"].accepted[0] == "an integer in [1, 1024]"  # its check's
    assert by_name["train", "eval_node_range"].accepted == ("a list of 2 integers, or null",)
    assert by_name["train: imitation", "planner"].default == "tour-scheduler"
    assert by_name["train-marl: phases[]", "agent_steps"].default == 100_000
