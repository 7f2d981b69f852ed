"""A policy folder that cannot carry code: tensors in safetensors, everything else in JSON.

    policy.json          format, schema version, algorithm, the env config it was trained
                         for, spaces, network, SHA-256 of every other file, training metadata
    weights.safetensors  the actor-critic's parameters (and, in training checkpoints, the
                         optimizer's state and the RNG states)
    normalization.json   the observation (and return) normalisation statistics

Loading checks the schema, every checksum, the spaces and the shapes before it builds the SB3
policy: nothing in the folder is ever unpickled. The normalisation statistics are part of the
policy; a folder without them is refused. SB3 zips and pickles (the legacy format) load only
with `trust_pickle=True` (`--trust-pickle` on the command line).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from safetensors import SafetensorError
from safetensors.torch import load_file, save_file
from stable_baselines3.common.policies import ActorCriticPolicy

from iout_mj.agents.shipped import MANIFEST
from iout_mj.agents.token_policy import TokenPolicy
from iout_mj.mission.tokens import observe_tokens

FORMAT = "iout-mj-policy"
SCHEMA_VERSION = 1
WEIGHTS = "weights.safetensors"
NORMALIZATION = "normalization.json"
MAX_JSON_BYTES = 1 << 20
"""policy.json and normalization.json are small; a larger file is refused unread."""


class PolicyFormatError(ValueError):
    """A policy folder is missing a file, damaged, or not in this format."""


@dataclass(frozen=True)
class Normalizer:
    """VecNormalize's observation transform: clip((obs - mean) / sqrt(var + eps), +-clip)."""

    mean: np.ndarray
    var: np.ndarray
    count: float
    clip_obs: float
    epsilon: float

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        x = (obs - self.mean) / np.sqrt(self.var + self.epsilon)
        return np.clip(x, -self.clip_obs, self.clip_obs).astype(np.float32)

    @classmethod
    def from_vec_normalize(cls, venv: Any) -> Normalizer:
        rms = venv.obs_rms
        return cls(rms.mean.copy(), rms.var.copy(), float(rms.count), venv.clip_obs, venv.epsilon)


@dataclass(frozen=True)
class LoadedPolicy:
    """A policy read from a folder: the SB3 policy, its normaliser and its manifest."""

    policy: ActorCriticPolicy
    normalizer: Normalizer
    manifest: dict[str, Any]
    stats: Any = None
    """The VecNormalize a legacy policy was read with (None in the safe format)."""

    def act(self, obs: np.ndarray) -> np.ndarray:
        """The deterministic action for one observation (or a batch) of the policy's kind."""
        action, _ = self.policy.predict(self.normalizer(obs), deterministic=True)
        return action

    @property
    def general(self) -> bool:
        """A general policy (any K up to its K_max) observing tokens."""
        return self.manifest.get("policy") == "tokens"

    def __call__(self, env: Any, obs: np.ndarray) -> np.ndarray:
        """The action in a gymnasium env (`rollout.EnvPolicy`): the env's observation, or
        for a general policy the token observation of its mission."""
        if self.general:
            mission = env.unwrapped.mission
            return self.act(observe_tokens(mission, self.manifest["k_max"]))
        return self.act(obs)


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def write_atomic(path: Path, data: bytes) -> None:
    """Write a file whole or not at all: a temporary file, fsync, rename."""
    tmp = path.with_name(path.name + ".tmp")
    with tmp.open("wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    tmp.replace(path)


def _json_bytes(data: Any) -> bytes:
    return (json.dumps(data, indent=2) + "\n").encode()


def save_policy(
    folder: Path,
    policy: ActorCriticPolicy,
    normalization: dict[str, Any],
    manifest: dict[str, Any],
    extra_tensors: dict[str, torch.Tensor] | None = None,
) -> None:
    """Write a policy folder, replaced whole: written beside it as `<folder>.tmp`, every file
    fsynced, then renamed over it.

    Args:
        folder: the policy folder.
        policy: the SB3 actor-critic.
        normalization: `normalization_dict(venv)` of its VecNormalize.
        manifest: JSON-able metadata (env config, training config, evaluation...).
        extra_tensors: more tensors for the weights file (optimizer state, RNG states).
    """
    tmp = folder.with_name(folder.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    tensors = {f"policy.{k}": v.detach().cpu().contiguous() for k, v in policy.state_dict().items()}
    tensors.update(extra_tensors or {})
    save_file(tensors, str(tmp / WEIGHTS))
    _fsync_file(tmp / WEIGHTS)
    write_atomic(tmp / NORMALIZATION, _json_bytes(normalization))
    obs_space, act_space = policy.observation_space, policy.action_space
    assert isinstance(obs_space, gym.spaces.Box) and isinstance(act_space, gym.spaces.MultiDiscrete)
    full = {
        "format": FORMAT,
        "schema_version": SCHEMA_VERSION,
        "algorithm": "PPO",
        "observation_size": int(obs_space.shape[0]),
        "action_nvec": [int(v) for v in act_space.nvec],
        **_network(policy),
        **manifest,
        "files": {name: sha256(tmp / name) for name in (WEIGHTS, NORMALIZATION)},
    }
    write_atomic(tmp / MANIFEST, _json_bytes(full))
    _fsync_dir(tmp)
    old = folder.with_name(folder.name + ".old")
    shutil.rmtree(old, ignore_errors=True)
    if folder.exists():
        folder.rename(old)
    tmp.rename(folder)  # a kill before this line leaves a complete <folder>.tmp
    shutil.rmtree(old, ignore_errors=True)
    _fsync_dir(folder.parent)


def _network(policy: ActorCriticPolicy) -> dict[str, Any]:
    """The manifest's description of the network (enough to rebuild it)."""
    if isinstance(policy, TokenPolicy):
        args = policy.token_args
        return {"policy": "tokens", "k_max": args["k_max"], "width": args["width"]}
    return {"policy": "mlp", "net_arch": policy.net_arch}


def _fsync_file(path: Path) -> None:
    with path.open("rb") as f:
        os.fsync(f.fileno())


def _fsync_dir(folder: Path) -> None:
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def normalization_dict(venv: Any) -> dict[str, Any]:
    """The VecNormalize statistics as plain JSON data."""
    out: dict[str, Any] = {
        "obs_mean": venv.obs_rms.mean.tolist(),
        "obs_var": venv.obs_rms.var.tolist(),
        "obs_count": float(venv.obs_rms.count),
        "clip_obs": float(venv.clip_obs),
        "epsilon": float(venv.epsilon),
    }
    if getattr(venv, "ret_rms", None) is not None:
        out.update(
            ret_mean=float(venv.ret_rms.mean),
            ret_var=float(venv.ret_rms.var),
            ret_count=float(venv.ret_rms.count),
            clip_reward=float(venv.clip_reward),
        )
    return out


def _read_json(path: Path) -> Any:
    if not path.is_file():
        raise PolicyFormatError(
            f"{path} is missing: a policy folder holds {MANIFEST}, {WEIGHTS} and {NORMALIZATION}"
        )
    if path.stat().st_size > MAX_JSON_BYTES:
        raise PolicyFormatError(f"{path} is larger than {MAX_JSON_BYTES} bytes")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise PolicyFormatError(f"{path} is not valid JSON: {exc}") from exc


def read_manifest(folder: Path) -> dict[str, Any]:
    """policy.json, checked: format, schema version, and every file's SHA-256."""
    manifest = _read_json(folder / MANIFEST)
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        raise PolicyFormatError(f"{folder / MANIFEST} is not an {FORMAT} manifest")
    if manifest.get("schema_version") != SCHEMA_VERSION:
        raise PolicyFormatError(
            f"{folder / MANIFEST}: schema_version {manifest.get('schema_version')!r}; "
            f"accepted {SCHEMA_VERSION}"
        )
    files = manifest.get("files")
    if not isinstance(files, dict) or set(files) != {WEIGHTS, NORMALIZATION}:
        raise PolicyFormatError(
            f"{folder / MANIFEST}: 'files' must list {WEIGHTS} and "
            f"{NORMALIZATION} with their SHA-256"
        )
    for name, digest in files.items():
        path = folder / name
        if not path.is_file():
            raise PolicyFormatError(
                f"{path} is missing (the normalisation statistics and the "
                "weights are part of the policy)"
            )
        if sha256(path) != digest:
            raise PolicyFormatError(
                f"{path} does not match the SHA-256 in {MANIFEST}: "
                "the file is damaged or was changed"
            )
    return manifest


def read_tensors(folder: Path) -> dict[str, torch.Tensor]:
    """Every tensor of the weights file (checksum already verified by `read_manifest`)."""
    try:
        return load_file(str(folder / WEIGHTS))
    except (SafetensorError, OSError) as exc:
        raise PolicyFormatError(
            f"{folder / WEIGHTS} is not a valid safetensors file: {exc}"
        ) from exc


def read_normalizer(folder: Path) -> Normalizer:
    data = _read_json(folder / NORMALIZATION)
    try:
        n = Normalizer(
            np.asarray(data["obs_mean"], dtype=np.float64),
            np.asarray(data["obs_var"], dtype=np.float64),
            float(data["obs_count"]),
            float(data["clip_obs"]),
            float(data["epsilon"]),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise PolicyFormatError(f"{folder / NORMALIZATION}: bad or missing field ({exc})") from exc
    if n.mean.shape != n.var.shape or n.mean.ndim != 1 or not np.all(np.isfinite(n.var)):
        raise PolicyFormatError(
            f"{folder / NORMALIZATION}: obs_mean and obs_var must be finite vectors of one length"
        )
    return n


def build_policy(manifest: dict[str, Any], tensors: dict[str, torch.Tensor]) -> ActorCriticPolicy:
    """The SB3 actor-critic of a manifest, with its weights (shapes checked)."""
    obs_space = gym.spaces.Box(
        -1.0, 2.0, shape=(int(manifest["observation_size"]),), dtype=np.float32
    )
    act_space = gym.spaces.MultiDiscrete(np.asarray(manifest["action_nvec"], dtype=np.int64))
    policy: ActorCriticPolicy
    try:
        if manifest.get("policy") == "tokens":
            k_max, width = int(manifest["k_max"]), int(manifest["width"])
            policy = TokenPolicy(obs_space, act_space, lambda _: 0.0, k_max=k_max, width=width)
        else:
            policy = ActorCriticPolicy(
                obs_space, act_space, lambda _: 0.0, net_arch=manifest.get("net_arch")
            )
    except (KeyError, TypeError, ValueError, RuntimeError) as exc:
        raise PolicyFormatError(f"the manifest's network cannot be built: {exc}") from exc
    state = {k[len("policy.") :]: v for k, v in tensors.items() if k.startswith("policy.")}
    try:
        policy.load_state_dict(state, strict=True)
    except RuntimeError as exc:
        raise PolicyFormatError(f"weights do not fit the manifest's network: {exc}") from exc
    policy.set_training_mode(False)
    return policy


def load_policy_folder(folder: Path) -> LoadedPolicy:
    """A policy folder, checked and built; raises `PolicyFormatError` saying what is wrong."""
    manifest = read_manifest(folder)
    normalizer = read_normalizer(folder)
    if normalizer.mean.shape[0] != manifest.get("observation_size"):
        raise PolicyFormatError(
            f"{folder / NORMALIZATION}: {normalizer.mean.shape[0]} "
            f"entries; the policy observes {manifest.get('observation_size')}"
        )
    return LoadedPolicy(build_policy(manifest, read_tensors(folder)), normalizer, manifest)
