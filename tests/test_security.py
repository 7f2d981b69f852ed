"""No file the project loads runs code; damaged or foreign policies give one clear error."""

import base64
import io
import json
import pickle
import shutil
import zipfile

import cloudpickle
import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from iout_mj.agents.policies import SHIPPED_DIR, PolicyError, load_policy, read_trained
from iout_mj.agents.policy_format import (
    MANIFEST,
    MANIFEST_SHA256,
    NORMALIZATION,
    WEIGHTS,
    load_policy_folder,
    sha256,
)
from iout_mj.envs import ENV_ID


class Payload:
    """Unpickling this creates `marker` (a stand-in for any code an attacker would run)."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def legacy_policy(folder, marker):
    """A legacy SB3 policy folder for N = 1, K = 7 whose zip and pickle both carry a payload."""
    env = gym.make(ENV_ID, backend="kinematic", n_auvs=1, n_nodes=7)
    venv = VecNormalize(DummyVecEnv([lambda: env]))
    PPO("MlpPolicy", venv, n_steps=8, batch_size=8, device="cpu").save(folder / "clean.zip")
    with (
        zipfile.ZipFile(folder / "clean.zip") as src,
        zipfile.ZipFile(folder / "model.zip", "w") as dst,
    ):
        for item in src.namelist():
            data = src.read(item)
            if item == "data":
                d = json.loads(data)
                blob = base64.b64encode(cloudpickle.dumps(Payload(marker))).decode()
                d["policy_kwargs"] = {":type:": "<class 'dict'>", ":serialized:": blob}
                data = json.dumps(d).encode()
            dst.writestr(item, data)
    (folder / "clean.zip").unlink()
    (folder / "vecnormalize.pkl").write_bytes(pickle.dumps(Payload(marker)))
    return folder


@pytest.fixture
def malicious(tmp_path):
    folder = tmp_path / "downloaded-policy"
    folder.mkdir()
    return legacy_policy(folder, tmp_path / "PWNED"), tmp_path / "PWNED"


def test_every_loading_path_refuses_a_pickled_policy(malicious, cli, tmp_path):
    folder, marker = malicious
    env = gym.make(ENV_ID, backend="kinematic", n_auvs=1, n_nodes=7)
    with pytest.raises(PolicyError, match="--trust-pickle"):
        load_policy(str(folder), env)
    for args in (
        ("evaluate", "--policy", folder, "--n-auvs", "1", "--episodes", "1"),
        ("mission", "--policy", folder, "--n-auvs", "1", "--no-video", "--out", tmp_path / "m"),
        ("render", "--policy", folder, "--n-auvs", "1", "--out", tmp_path / "r"),
    ):
        out = cli(*args, check=False)
        assert out.returncode == 2 and "--trust-pickle" in out.stderr, out.stderr
    run = tmp_path / "run"
    (run / "last").mkdir(parents=True)
    for name in ("model.zip", "vecnormalize.pkl"):
        shutil.copy(folder / name, run / "last" / name)
    (run / "config.yaml").write_text("name: t\nn_auvs: 1\n")
    out = cli("train", run / "config.yaml", "--out", run, "--resume", check=False)
    assert out.returncode == 2 and "no complete last/ checkpoint" in out.stderr
    assert not marker.exists()


def test_trusting_a_pickle_is_explicit_and_works(tmp_path):
    folder = tmp_path / "legacy"
    folder.mkdir()
    env = gym.make(ENV_ID, backend="kinematic", n_auvs=1, n_nodes=7)
    venv = VecNormalize(DummyVecEnv([lambda: env]))
    PPO("MlpPolicy", venv, n_steps=8, batch_size=8, device="cpu").save(folder / "model.zip")
    venv.save(str(folder / "vecnormalize.pkl"))
    policy = load_policy(str(folder), env, trust_pickle=True)
    obs, _ = env.reset(seed=0)
    assert env.action_space.contains(policy(env, obs))
    (folder / "vecnormalize.pkl").unlink()
    with pytest.raises(PolicyError, match=r"vecnormalize\.pkl is missing"):
        load_policy(str(folder), env, trust_pickle=True)


def test_loading_a_shipped_policy_never_unpickles(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("unpickling during a safe load")

    monkeypatch.setattr(pickle, "load", refuse)
    monkeypatch.setattr(pickle, "loads", refuse)
    monkeypatch.setattr(pickle, "Unpickler", refuse)
    loaded = load_policy_folder(SHIPPED_DIR / "ppo-n2-k7")
    assert loaded.act(np.zeros(loaded.manifest["observation_size"], np.float32)).shape == (8,)


@pytest.fixture
def copy_of_shipped(tmp_path):
    folder = tmp_path / "p"
    shutil.copytree(SHIPPED_DIR / "ppo-n1-k7", folder)
    return folder


def _reseal(folder):
    """policy.json's sidecar recomputed, as a deliberate editor would (sha256sum > ...)."""
    digest = sha256(folder / MANIFEST)
    (folder / MANIFEST_SHA256).write_text(f"{digest}  {MANIFEST}\n")


def _rehash(folder):
    manifest = json.loads((folder / MANIFEST).read_text())
    manifest["files"] = {name: sha256(folder / name) for name in manifest["files"]}
    (folder / MANIFEST).write_text(json.dumps(manifest))
    _reseal(folder)


def _rewrite(folder, text):
    (folder / MANIFEST).write_text(text)
    _reseal(folder)


@pytest.mark.parametrize(
    ("damage", "match"),
    [
        (lambda f: (f / NORMALIZATION).unlink(), "normalization.json is missing"),
        (lambda f: (f / WEIGHTS).write_bytes((f / WEIGHTS).read_bytes()[:-9]), "SHA-256"),
        (
            lambda f: ((f / WEIGHTS).write_bytes((f / WEIGHTS).read_bytes()[:5000]), _rehash(f)),
            "not a valid safetensors",
        ),
        (
            lambda f: (f / MANIFEST).write_text((f / MANIFEST).read_text().replace("256", "257")),
            "does not match its SHA-256 in policy.json.sha256",
        ),
        (lambda f: (f / MANIFEST_SHA256).unlink(), "policy.json.sha256 is missing"),
        (lambda f: (f / MANIFEST_SHA256).write_text("0" * 64), "not a checksum line"),
        (lambda f: _rewrite(f, "{"), "not valid JSON"),
        (lambda f: _rewrite(f, "[" * 100_000), "nested too deeply"),
        (lambda f: _rewrite(f, '{"format": "other"}'), "not an iout-mj-policy"),
        (
            lambda f: _rewrite(
                f, (f / MANIFEST).read_text().replace('"schema_version": 1', '"schema_version": 9')
            ),
            "schema_version 9",
        ),
        (
            lambda f: (
                (f / NORMALIZATION).write_text(json.dumps({"obs_mean": [0.0]})),
                _rehash(f),
            ),
            "bad or missing field",
        ),
    ],
)
def test_damaged_policy_folders_give_one_clear_error(copy_of_shipped, damage, match):
    damage(copy_of_shipped)
    env = gym.make(ENV_ID, backend="kinematic", n_auvs=1, n_nodes=7)
    with pytest.raises(PolicyError, match=match):
        read_trained(str(copy_of_shipped), env)


def test_a_policy_refuses_another_action_mapping(copy_of_shipped):
    env = gym.make(
        ENV_ID,
        backend="kinematic",
        n_auvs=1,
        n_nodes=7,
        config={"motion": {"dtheta_max_deg": 15.0}},
    )
    with pytest.raises(PolicyError, match=r"motion.dtheta_max_deg=25.0; this env has 15.0"):
        read_trained(str(copy_of_shipped), env)


def test_policy_manifest_records_the_env_config():
    manifest = json.loads((SHIPPED_DIR / "ppo-n2-k7" / MANIFEST).read_text())
    assert manifest["env_config"]["scenario"]["n_auvs"] == 2
    assert set(manifest["files"]) == {WEIGHTS, NORMALIZATION}
    sidecar = (SHIPPED_DIR / "ppo-n2-k7" / MANIFEST_SHA256).read_text()
    assert sidecar == f"{sha256(SHIPPED_DIR / 'ppo-n2-k7' / MANIFEST)}  {MANIFEST}\n"
    raw = io.BytesIO((SHIPPED_DIR / "ppo-n2-k7" / WEIGHTS).read_bytes())
    assert raw.read(8)  # safetensors: an 8-byte header length, a JSON header, raw tensors


@settings(
    max_examples=40,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(
    name=st.sampled_from([MANIFEST, MANIFEST_SHA256, WEIGHTS, NORMALIZATION]),
    position=st.floats(0, 1, exclude_max=True),
    byte=st.integers(0, 255),
)
def test_any_changed_byte_is_refused(tmp_path_factory, name, position, byte):
    folder = tmp_path_factory.mktemp("p") / "policy"
    shutil.copytree(SHIPPED_DIR / "ppo-n1-k7", folder)
    data = bytearray((folder / name).read_bytes())
    i = int(position * len(data))
    changed = data[i] != byte
    data[i] = byte
    (folder / name).write_bytes(bytes(data))
    env = gym.make(ENV_ID, backend="kinematic", n_auvs=1, n_nodes=7)
    try:
        loaded = read_trained(str(folder), env)
    except PolicyError as exc:
        assert changed and str(folder) in str(exc)
        return
    # every file is covered by a checksum, the manifest by its sidecar: only an unchanged byte
    # is accepted
    assert not changed
    assert loaded.manifest["observation_size"] == env.observation_space.shape[0]
