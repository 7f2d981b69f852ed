"""Policy and checkpoint folders as an attacker or a failing disk leaves them: edited JSON,
links to /proc, FIFOs and devices, huge declared sizes, sparse huge files, a full disk and a
kill in the middle of a write. Each gives one clear error or a recovered checkpoint."""

import hashlib
import json
import os
import shutil
import stat
import tracemalloc

import gymnasium as gym
import pytest
from conftest import tiny_training
from stable_baselines3.common.policies import ActorCriticPolicy

from iout_mj.agents.policies import SHIPPED_DIR, read_trained
from iout_mj.agents.policy_bounds import (
    MAX_PARAMETERS,
    mlp_parameters,
    token_parameters,
)
from iout_mj.agents.policy_format import (
    MANIFEST,
    MANIFEST_SHA256,
    MAX_WEIGHTS_BYTES,
    NORMALIZATION,
    WEIGHTS,
    build_policy,
    load_policy_folder,
    read_manifest,
    read_tensors,
    save_policy,
    sha256,
)
from iout_mj.agents.token_policy import TokenPolicy
from iout_mj.envs import ENV_ID
from iout_mj.errors import CheckpointError, PolicyError
from iout_mj.files import CHUNK_BYTES
from iout_mj.mission.tokens import token_size
from iout_mj.training import PhaseConfig, train
from iout_mj.training.checkpoints import export_policy, read_run_state, recover


def seal(folder):
    """Recompute every checksum after an edit, as a deliberate editor would."""
    manifest = json.loads((folder / MANIFEST).read_text())
    manifest["files"] = {name: sha256(folder / name) for name in (WEIGHTS, NORMALIZATION)}
    data = (json.dumps(manifest) + "\n").encode()
    (folder / MANIFEST).write_bytes(data)
    (folder / MANIFEST_SHA256).write_text(f"{hashlib.sha256(data).hexdigest()}  {MANIFEST}\n")


def edit_manifest(folder, reseal=True, **changes):
    manifest = json.loads((folder / MANIFEST).read_text())
    for key, value in changes.items():
        target = manifest
        *path, last = key.split("__")
        for part in path:
            target = target[part]
        target[last] = value
    (folder / MANIFEST).write_text(json.dumps(manifest))
    if reseal:
        seal(folder)


@pytest.fixture
def policy(tmp_path):
    folder = tmp_path / "policy"
    shutil.copytree(SHIPPED_DIR / "ppo-n1-k7", folder)
    return folder


def small_config():
    phases = (PhaseConfig("kinematic", 64), PhaseConfig("kinematic", 64))
    return tiny_training(n_steps=32, eval_every_steps=64, phases=phases)


@pytest.fixture(scope="module")
def trained_run(tmp_path_factory):
    """A finished two-phase run (about a second)."""
    out = tmp_path_factory.mktemp("run") / "run"
    train(small_config(), out, progress=False, parallel=False)
    return out


@pytest.fixture
def run(trained_run, tmp_path):
    out = tmp_path / "run"
    shutil.copytree(trained_run, out)
    return out


# 1. hashes streamed, weights capped before hashing


def test_the_hash_is_streamed_in_chunks(tmp_path):
    path = tmp_path / "big"
    with path.open("wb") as f:
        f.truncate(64 * CHUNK_BYTES)  # sparse: 64 MiB of zeros
    expected = hashlib.sha256()
    for _ in range(64):
        expected.update(bytes(CHUNK_BYTES))
    tracemalloc.start()
    digest = sha256(path)
    peak_bytes = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert digest == expected.hexdigest()
    assert peak_bytes < 4 * CHUNK_BYTES  # a whole-file read would hold 64 chunks


def test_a_huge_sparse_weights_file_is_refused_before_it_is_hashed(policy):
    with (policy / WEIGHTS).open("r+b") as f:
        f.truncate(30 << 30)  # 30 GiB, sparse
    with pytest.raises(PolicyError, match=f"holds {30 << 30} bytes: accepted at most "):
        load_policy_folder(policy)
    assert MAX_WEIGHTS_BYTES < 30 << 30


# 2. every JSON covered by a checksum, checkpoints included


def test_an_edited_checkpoint_manifest_is_refused_on_resume(run):
    edit_manifest(run / "last", reseal=False, run_state__num_timesteps=10**12)
    state_before = (run / "state.json").read_text()
    edited = r"policy.json does not match its SHA-256"
    with pytest.raises((CheckpointError, PolicyError), match=edited):
        train(small_config(), run, resume=True, progress=False, parallel=False)
    assert (run / "state.json").read_text() == state_before  # nothing trained


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"run_state__phase": 99}, r"run_state.phase is 99; accepted an integer in \[0, 2\]"),
        ({"run_state__phase": -1}, r"run_state.phase is -1"),
        ({"run_state__num_timesteps": 10**12}, "run_state.num_timesteps is 1000000000000"),
        ({"run_state__best_score": "high"}, "best_score is 'high'"),
        ({"run_state": [1, 2]}, "run_state must hold phase"),
    ],
)
def test_a_resealed_run_state_out_of_the_config_is_refused(run, changes, match):
    edit_manifest(run / "last", **changes)
    with pytest.raises(CheckpointError, match=match):
        read_run_state(run / "last", small_config())


def test_an_edited_normalization_json_is_refused(run):
    path = run / "last" / NORMALIZATION
    path.write_text(path.read_text().replace("[", "[1e300, ", 1))
    with pytest.raises(CheckpointError, match=r"normalization.json does not match the SHA-256"):
        read_run_state(run / "last", small_config())


def test_a_resealed_non_finite_normalization_is_refused(policy):
    stats = json.loads((policy / NORMALIZATION).read_text())
    stats["obs_var"][3] = -1.0
    (policy / NORMALIZATION).write_text(json.dumps(stats))
    seal(policy)
    with pytest.raises(PolicyError, match="negative variance"):
        load_policy_folder(policy)
    stats["obs_var"][3], stats["clip_obs"] = 1.0, float("nan")
    (policy / NORMALIZATION).write_text(json.dumps(stats))
    seal(policy)
    with pytest.raises(PolicyError, match="clip_obs is nan; accepted a finite number > 0"):
        load_policy_folder(policy)


# 3. sizes bounded before anything is allocated


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"net_arch": [100_000, 100_000]}, r"net_arch\[0\] is 100000; accepted an integer in"),
        ({"net_arch": [1 << 14] * 4}, r"would allocate 1,612,[\d,]+ parameters; accepted at most"),
        ({"net_arch": [64] * 1000}, "a list of at most 16 widths"),
        ({"net_arch": {"pi": [1 << 14] * 3}}, "would allocate"),
        ({"observation_size": 10**10}, r"observation_size is 10000000000; accepted an integer"),
        ({"action_nvec": [10**9, 7, 7, 7]}, r"action_nvec\[0\] is 1000000000"),
        ({"action_nvec": [11] * 100_000}, "a list of 1 to 256 action sizes"),
        ({"net_arch": [True]}, r"net_arch\[0\] is True"),
        ({"policy": "convolution"}, "accepted 'mlp' or 'tokens'"),
    ],
)
def test_huge_declared_sizes_are_refused_before_building(policy, changes, match):
    edit_manifest(policy, **changes)
    with pytest.raises(PolicyError, match=match):
        load_policy_folder(policy)


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"k_max": 1000, "width": 1 << 14}, "would allocate"),
        ({"k_max": 5000}, r"k_max is 5000; accepted an integer in \[1, 1024\]"),
        ({"width": 6}, "accepted a multiple of 4"),
        ({"action_nvec": [11, 7, 30, 29, 11, 7, 30, 30]}, "does not fit a token policy"),
        ({"observation_size": 100}, "a token policy for N=2, k_max=30 observes"),
    ],
)
def test_a_token_manifest_is_bounded_too(tmp_path, changes, match):
    folder = tmp_path / "general"
    shutil.copytree(SHIPPED_DIR / "ppo-general-n2", folder)
    manifest = json.loads((folder / MANIFEST).read_text())
    if "k_max" in changes:  # keep the declared spaces consistent: only the size is wrong
        n_auvs, k = manifest["n_auvs"], changes["k_max"]
        changes = {**changes, "observation_size": min(token_size(n_auvs, k), 1 << 16)}
        changes["action_nvec"] = [*manifest["action_nvec"][:2], k, k]
        changes["action_nvec"] *= n_auvs
    edit_manifest(folder, **changes)
    with pytest.raises(PolicyError, match=match):
        load_policy_folder(folder)


def test_export_refuses_a_huge_network(run, tmp_path):
    edit_manifest(run / "best", net_arch=[1 << 14] * 8)
    with pytest.raises(CheckpointError, match=r"cannot export .*would allocate"):
        export_policy(run / "best", tmp_path / "shipped")
    assert not (tmp_path / "shipped").exists()


def test_export_refuses_to_replace_a_folder_that_is_not_a_policy(run, tmp_path):
    mine = tmp_path / "documents"
    mine.mkdir()
    (mine / "thesis.tex").write_text("years of work")
    with pytest.raises(PolicyError, match="exists and is not a policy folder"):
        export_policy(run / "best", mine)
    assert (mine / "thesis.tex").read_text() == "years of work"


def _built_parameters(policy):
    return sum(p.numel() for p in policy.parameters())


@pytest.mark.parametrize("name", ["ppo-n1-k7", "ppo-n2-k7", "ppo-general-n1", "ppo-general-n2"])
def test_the_parameter_count_is_that_of_the_built_network(name):
    folder = SHIPPED_DIR / name
    manifest = read_manifest(folder)
    built = _built_parameters(build_policy(manifest, read_tensors(folder, manifest)))
    nvec = manifest["action_nvec"]
    if manifest.get("policy") == "tokens":
        n, k = len(nvec) // 4, manifest["k_max"]
        logits = n * (nvec[0] + nvec[1] + 2 * k)
        transient = logits * logits + logits  # SB3's action head, replaced by the identity
        assert token_parameters(n, k, nvec[0], nvec[1], manifest["width"]) == built + transient
    else:
        assert mlp_parameters(manifest["observation_size"], nvec, manifest["net_arch"], "") == built


@pytest.mark.parametrize(
    "net_arch", [None, [], [5], [7, 3, 9], {"pi": [4, 6], "vf": [3]}, {"vf": [8]}]
)
def test_the_mlp_count_matches_sb3_for_every_net_arch_form(net_arch):
    obs, act = gym.spaces.Box(-1, 2, (13,)), gym.spaces.MultiDiscrete([11, 7, 5, 5, 3])
    built = ActorCriticPolicy(obs, act, lambda _: 0.0, net_arch=net_arch)
    assert mlp_parameters(13, [11, 7, 5, 5, 3], net_arch, "") == _built_parameters(built)


def test_the_token_count_matches_for_other_sizes():
    n, k, width = 3, 5, 8
    nvec = [4, 3, k, k] * n
    obs = gym.spaces.Box(-1, 2, (token_size(n, k),))
    built = TokenPolicy(obs, gym.spaces.MultiDiscrete(nvec), lambda _: 0.0, k_max=k, width=width)
    logits = n * (4 + 3 + 2 * k)
    transient = logits * logits + logits
    assert token_parameters(n, k, 4, 3, width) == _built_parameters(built) + transient
    assert token_parameters(n, k, 4, 3, width) < MAX_PARAMETERS


# 4. links and special files refused


def _link(target):
    def make(path):
        path.unlink()
        path.symlink_to(target)

    return make


def _fifo(path):
    path.unlink()
    os.mkfifo(path)


def _folder(path):
    path.unlink()
    path.mkdir()


@pytest.mark.parametrize(
    ("name", "make", "match"),
    [
        (MANIFEST, _link("/proc/self/environ"), "policy.json is a symbolic link"),
        (WEIGHTS, _link("/proc/self/pagemap"), "weights.safetensors is a symbolic link"),
        (NORMALIZATION, _link("/dev/zero"), "normalization.json is a symbolic link"),
        (MANIFEST_SHA256, _link("/dev/stdin"), "policy.json.sha256 is a symbolic link"),
        (NORMALIZATION, _fifo, "normalization.json is a FIFO: accepted a regular file only"),
        (WEIGHTS, _fifo, "weights.safetensors is a FIFO"),
        (WEIGHTS, _folder, "weights.safetensors is a folder"),
    ],
)
def test_links_and_special_files_are_refused(policy, name, make, match):
    make(policy / name)
    env = gym.make(ENV_ID, backend="kinematic", n_auvs=1, n_nodes=7)
    with pytest.raises(PolicyError, match=match):
        read_trained(str(policy), env)


def test_a_device_node_is_refused(policy):
    (policy / WEIGHTS).unlink()
    try:
        os.mknod(policy / WEIGHTS, 0o600 | stat.S_IFCHR, os.makedev(1, 5))  # /dev/zero
    except PermissionError:
        pytest.skip("creating a device node needs CAP_MKNOD")
    with pytest.raises(PolicyError, match=r"weights.safetensors is a character device"):
        load_policy_folder(policy)


def test_the_command_line_reports_a_linked_file_without_a_traceback(policy, cli):
    _link("/proc/self/pagemap")(policy / WEIGHTS)
    out = cli("evaluate", "--policy", policy, "--n-auvs", "1", "--episodes", "1", check=False)
    assert out.returncode == 2 and "weights.safetensors is a symbolic link" in out.stderr
    assert "Traceback" not in out.stderr


def test_a_fifo_in_a_checkpoint_is_refused_on_resume(run):
    _fifo(run / "last" / NORMALIZATION)
    recover(run / "last")  # must not block on the FIFO, nor replace the damaged folder
    with pytest.raises(CheckpointError, match=r"normalization.json is a FIFO"):
        read_run_state(run / "last", small_config())


# 6. interrupted writes: every state a kill can leave is recovered


def _partial(folder):
    """What a kill leaves mid-write: some files, no manifest."""
    folder.mkdir()
    (folder / WEIGHTS).write_bytes(b"\0" * 100)


def _phase(folder):
    return read_manifest(folder)["run_state"]["phase"]


def test_a_kill_while_writing_keeps_the_old_checkpoint(run):
    _partial(run / "last.tmp")
    recover(run / "last")
    assert _phase(run / "last") == 2 and not (run / "last.tmp").exists()


def test_a_kill_between_the_renames_puts_the_new_checkpoint_back(run):
    (run / "last").rename(run / "last.tmp")  # the new one, complete
    _partial(run / "last.old")  # the old one, half removed
    recover(run / "last")
    assert _phase(run / "last") == 2
    assert not (run / "last.tmp").exists() and not (run / "last.old").exists()


def test_a_kill_with_only_the_old_checkpoint_complete_puts_it_back(run):
    (run / "last").rename(run / "last.old")
    _partial(run / "last.tmp")
    recover(run / "last")
    assert _phase(run / "last") == 2 and sorted(p.name for p in run.glob("last*")) == ["last"]


def test_a_damaged_checkpoint_is_not_replaced_silently(run):
    edit_manifest(run / "last", reseal=False, run_state__phase=0)
    shutil.copytree(run / "best", run / "last.old")
    recover(run / "last")
    assert (run / "last.old").exists()  # left for the user: loading reports the damage
    with pytest.raises(PolicyError, match="does not match its SHA-256"):
        read_manifest(run / "last")


def test_a_new_policy_folder_replaces_the_old_whole(policy, tmp_path):
    loaded = load_policy_folder(policy)
    stats = json.loads((policy / NORMALIZATION).read_text())
    save_policy(policy, loaded.policy, stats, {"n_auvs": 1, "n_nodes": 7, "note": "second"})
    assert read_manifest(policy)["note"] == "second"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["policy"]


def test_export_writes_a_policy_that_acts_as_the_checkpoint(run, tmp_path):
    kept = export_policy(run / "best", tmp_path / "shipped")
    shipped, checkpoint = load_policy_folder(tmp_path / "shipped"), load_policy_folder(run / "best")
    assert "rng" not in shipped.manifest and kept["eval_at_selection"]["num_timesteps"] > 0
    obs = checkpoint.normalizer.mean.astype("float32")
    assert (shipped.act(obs) == checkpoint.act(obs)).all()
    assert sorted(p.name for p in (tmp_path / "shipped").iterdir()) == sorted(
        [MANIFEST, MANIFEST_SHA256, WEIGHTS, NORMALIZATION]
    )
