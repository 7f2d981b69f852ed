"""Ray: evaluation episodes as tasks (the same rows as the local pool) and a Tune sweep whose
trials are the project's trainer, on a local Ray instance bound to loopback."""

import json
import os
import socket
import time

import pytest
import ray
from conftest import ROOT, run_cli

from iout_mj.errors import UsageError
from iout_mj.experiments import ray_jobs
from iout_mj.experiments.evaluate import evaluate
from iout_mj.schema import ConfigError

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def local_ray():
    ray_jobs.connect("local")
    yield
    ray.shutdown()


def test_evaluation_on_ray_gives_the_rows_of_the_local_pool(local_ray):
    args = (["greedy", "tour-scheduler"], [1, 2], [7], 2, 3, "kinematic")
    local, local_eps = evaluate(*args, workers=1, progress=False)
    remote, remote_eps = evaluate(*args, progress=False, ray_address="local")
    assert remote == local
    key = lambda e: (e["policy"], e["n_auvs"], e["seed"])  # noqa: E731
    assert json.dumps(sorted(remote_eps, key=key)) == json.dumps(sorted(local_eps, key=key))


def test_the_local_instances_workers_run_at_the_callers_priority(local_ray):
    """Not Ray's default nice 15, at which a busy machine starves the tasks."""
    niceness = ray.remote(num_cpus=1)(lambda: os.nice(0))
    assert ray.get(niceness.remote()) == os.nice(0)


def test_a_two_trial_sweep_writes_results_and_resumes(local_ray, tmp_path):
    sweep_file = ROOT / "training" / "configs" / "sweep-smoke.yaml"
    result = ray_jobs.sweep(sweep_file, tmp_path, "local")
    assert sorted(r["trial"] for r in result["trials"]) == ["smoke-0", "smoke-1"]
    assert all(r["num_timesteps"] == 512 for r in result["trials"])
    assert (tmp_path / "results.csv").read_text().startswith("trial,seed,")
    assert "seed:" in (tmp_path / "best.yaml").read_text()
    for trial in ("smoke-0", "smoke-1"):  # each trial is a run folder of the trainer
        assert (tmp_path / trial / "last" / "policy.json").is_file()
    again = ray_jobs.sweep(sweep_file, tmp_path, "local")  # resumed: nothing left to train
    assert again["trials"] == result["trials"]


def test_bad_sweep_files_are_clear(tmp_path):
    bad = tmp_path / "s.yaml"
    bad.write_text(f"base: {ROOT / 'training' / 'configs' / 'smoke.yaml'}\ngrid: {{gamma: []}}\n")
    with pytest.raises(ConfigError, match="non-empty list"):
        ray_jobs.load_sweep(bad)
    bad.write_text(f"base: {ROOT / 'training' / 'configs' / 'smoke.yaml'}\ngrid: {{speed: [1]}}\n")
    with pytest.raises(ConfigError, match="accepted fields of the training config"):
        ray_jobs.load_sweep(bad)


@pytest.fixture
def no_ray():
    """No Ray connection yet (`connect` keeps the one it has)."""
    ray.shutdown()


def unused_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("scheme", ["", "ray://"])
def test_nothing_listening_at_the_address_is_a_clear_error_at_once(no_ray, scheme):
    address = f"{scheme}127.0.0.1:{unused_port()}"
    start = time.perf_counter()
    with pytest.raises(UsageError, match=rf"cannot reach a Ray cluster at {address}.*accepted"):
        ray_jobs.connect(address, timeout_s=3)
    assert time.perf_counter() - start < 3
    assert not ray.is_initialized()


@pytest.mark.parametrize("address", ["nonsense", "127.0.0.1:", "127.0.0.1:99999", ":6379"])
def test_a_malformed_address_says_what_is_accepted(no_ray, address):
    with pytest.raises(UsageError, match=r"is invalid: accepted 'local'.*HOST:PORT"):
        ray_jobs.connect(address)


def test_evaluate_gives_up_on_a_port_that_is_not_ray(tmp_path):
    """Something listens (the kernel accepts the connection) but never speaks Ray: without a
    timeout Ray retries for ever."""
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen(8)
        address = f"127.0.0.1:{listener.getsockname()[1]}"
        start = time.perf_counter()
        out = run_cli(
            *("evaluate", "--policy", "greedy", "--n-auvs", "1", "--episodes", "1"),
            *("--backend", "kinematic", "--ray", address, "--ray-timeout", "3"),
            check=False,
        )
        elapsed = time.perf_counter() - start
    assert out.returncode == 2, out.stderr
    assert f"no Ray cluster answered at {address} within 3 s" in out.stderr
    assert "Traceback" not in out.stderr
    assert elapsed < 40  # imports and the policy check, then 3 s (before: never returned)
