"""Real faults while a checkpoint or policy is written, in a child process: a file-size limit
(EFBIG), a full tmpfs (ENOSPC, where a mount namespace can be made) and SIGKILL at random
moments. The result is one clear error or a recovered folder, never a broken one or a
leftover temporary folder."""

import json
import shutil
import subprocess
import sys
import textwrap

import pytest

from iout_mj.agents.policies import SHIPPED_DIR

FULL_DISK = textwrap.dedent(
    """
    import json, resource, sys
    from pathlib import Path
    from stable_baselines3.common.vec_env import VecNormalize
    from iout_mj.agents.policy_format import read_manifest
    from iout_mj.errors import CheckpointError
    from iout_mj.training import PhaseConfig, TrainConfig
    from iout_mj.training.checkpoints import RunState, save_checkpoint
    from iout_mj.training.trainer import new_model, vec_env

    out, mode = Path(sys.argv[1]), sys.argv[2]
    cfg = TrainConfig(name="t", n_auvs=1, n_nodes=7, n_envs=2, n_steps=32, batch_size=64,
                      phases=(PhaseConfig("kinematic", 64),))
    model = new_model(cfg, VecNormalize(vec_env(cfg, "kinematic", 2, 0, False)))
    save_checkpoint(model, out / "last", cfg, RunState(phase=0), {})
    if mode == "efbig":  # any write past 64 bytes fails: the weights, and state.json
        resource.setrlimit(resource.RLIMIT_FSIZE, (64, resource.RLIM_INFINITY))
    errors = []
    try:
        save_checkpoint(model, out / "last", cfg, RunState(phase=1), {})
    except CheckpointError as exc:
        errors.append(str(exc))
    if mode == "efbig":
        try:
            RunState(phase=1, history=[{"mean_aoi": 1.0}] * 9).save(out / "state.json")
        except CheckpointError as exc:
            errors.append(str(exc))
    print(json.dumps({
        "errors": errors,
        "files": sorted(p.name for p in out.iterdir()),
        "phase": read_manifest(out / "last")["run_state"]["phase"],
    }))
    """
)


def _run(args):
    out = subprocess.run(args, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.splitlines()[-1])


def test_a_file_size_limit_gives_one_clear_error_and_keeps_the_checkpoint(tmp_path):
    (tmp_path / "run").mkdir()
    result = _run([sys.executable, "-c", FULL_DISK, str(tmp_path / "run"), "efbig"])
    write, state = result["errors"]
    assert write.startswith(f"cannot write checkpoint {tmp_path / 'run' / 'last'}: File too large")
    assert write.endswith("the previous checkpoint (if any) is kept")
    assert state == f"cannot write {tmp_path / 'run' / 'state.json'}: File too large"
    assert result["files"] == ["last"]  # no last.tmp, no state.json.tmp
    assert result["phase"] == 0  # the previous checkpoint, whole


def test_a_full_disk_gives_one_clear_error_and_keeps_the_checkpoint(tmp_path):
    if (
        shutil.which("unshare") is None
        or subprocess.run(["unshare", "-rm", "true"], capture_output=True).returncode
    ):
        pytest.skip("no user and mount namespaces here to mount a small tmpfs")
    (tmp_path / "run").mkdir()
    mount = 'mount -t tmpfs -o size=1m tmpfs "$1" && exec "$2" -c "$3" "$1" enospc'
    result = _run(
        ["unshare", "-rm", "sh", "-c", mount, "sh", tmp_path / "run", sys.executable, FULL_DISK]
    )
    (write,) = result["errors"]
    assert "cannot write checkpoint" in write and "No space left on device" in write
    assert result["files"] == ["last"] and result["phase"] == 0


KILLS = textwrap.dedent(
    """
    import json, os, random, signal, sys, time
    import torch
    torch.set_num_threads(1)
    from pathlib import Path
    from iout_mj.agents.policy_format import load_policy_folder, read_manifest, save_policy
    from iout_mj.training.checkpoints import recover

    src, folder = Path(sys.argv[1]), Path(sys.argv[2])
    loaded = load_policy_folder(src)
    stats = json.loads((src / "normalization.json").read_text())
    pad = {"pad": torch.zeros(1 << 21)}  # 8 MB: writes long enough to be cut
    save_policy(folder, loaded.policy, stats, {"i": -1}, pad)
    rng, trials = random.Random(0), []
    for _ in range(int(sys.argv[3])):
        pid = os.fork()
        if pid == 0:
            for i in range(10**9):
                save_policy(folder, loaded.policy, stats, {"i": i}, pad)
        time.sleep(rng.uniform(0.0, 0.25))
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        left = sorted(p.name for p in folder.parent.iterdir())
        recover(folder)
        load_policy_folder(folder)  # every checksum, the network built
        trials.append({"left": left, "after": sorted(p.name for p in folder.parent.iterdir()),
                       "i": read_manifest(folder)["i"]})
    print(json.dumps(trials))
    """
)


def test_a_kill_at_any_moment_of_a_write_leaves_a_whole_folder(tmp_path):
    (tmp_path / "out").mkdir()
    args = [SHIPPED_DIR / "ppo-n1-k7", tmp_path / "out" / "policy", 12]
    trials = _run([sys.executable, "-c", KILLS, *map(str, args)])
    assert all(t["after"] == ["policy"] for t in trials)  # recovered, nothing left over
    assert all(t["i"] >= -1 for t in trials)
    assert any(t["left"] != ["policy"] for t in trials)  # some kills cut a write
