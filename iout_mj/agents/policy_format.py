"""A policy folder that cannot carry code: tensors in safetensors, everything else in JSON.

    policy.json          format, schema version, algorithm, the env config it was trained
                         for, spaces, network, SHA-256 of every other file, training metadata
    policy.json.sha256   SHA-256 of policy.json itself (`sha256sum -c` reads it)
    weights.safetensors  the actor-critic's parameters (and, in training checkpoints, the
                         optimizer's state and the RNG states)
    normalization.json   the observation (and return) normalisation statistics

Every file is covered by a checksum: policy.json by its sidecar, the others by policy.json, so
an edited or damaged file (a checkpoint's run state included) is refused with its name. The
manifest's own checksum lives beside it, not in it: a hash over the exact bytes, which
`sha256sum` can check, with no canonical form of JSON to define. Loading reads regular files
only (a symbolic link, FIFO or device is refused), caps every size before reading or hashing
(hashes are streamed), bounds the network the manifest describes before building it
(`policy_bounds`), and checks the spaces and shapes: nothing in the folder is ever unpickled.
The normalisation statistics are part of the policy; a folder without them is refused. SB3 zips
and pickles (the legacy format) load only with `trust_pickle=True` (`--trust-pickle`).

Writing is whole or not at all: the folder is written as `<folder>.tmp`, every file fsynced,
then swapped in by renames (`training.checkpoints.recover` finishes a swap a kill interrupted);
a failed write (no space left, file too large) removes `<folder>.tmp` and raises `PolicyError`
with the OS's reason, leaving the previous folder as it was.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from safetensors import SafetensorError
from safetensors.torch import load as load_tensors
from safetensors.torch import save as tensor_bytes
from stable_baselines3.common.policies import ActorCriticPolicy

from iout_mj.agents.policy_bounds import check_network
from iout_mj.agents.shipped import MANIFEST
from iout_mj.agents.token_policy import TokenPolicy
from iout_mj.errors import PolicyError, PolicyMismatchError
from iout_mj.errors import PolicyFormatError as PolicyFormatError  # re-exported
from iout_mj.files import fsync_dir, parse_json, read_capped, remove, sha256_file, write_new
from iout_mj.files import write_atomic as write_atomic  # re-exported

FORMAT = "iout-mj-policy"
SCHEMA_VERSION = 1
WEIGHTS = "weights.safetensors"
NORMALIZATION = "normalization.json"
MANIFEST_SHA256 = MANIFEST + ".sha256"
FILES = (MANIFEST, MANIFEST_SHA256, WEIGHTS, NORMALIZATION)
"""Every file of a policy folder."""
MAX_JSON_BYTES = 1 << 20
"""policy.json and normalization.json are small; a larger file is refused unread."""
MAX_WEIGHTS_BYTES = 256 << 20
"""MAX_PARAMETERS in float32 three times over (weights and Adam's two moments), and room for
the RNG states: a larger weights file is refused before it is hashed."""
MAX_SIDECAR_BYTES = 4096
_SIDECAR = re.compile(r"([0-9a-f]{64})  " + re.escape(MANIFEST) + r"\n?")


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
        """The deterministic action for one observation (or a batch) of the policy's kind
        (`check_observation`)."""
        self.check_observation(obs)
        action, _ = self.policy.predict(self.normalizer(obs), deterministic=True)
        return action

    def check_observation(self, obs: np.ndarray) -> None:
        """Refuse an observation (or a batch) the policy cannot read: O(1) in its size, and
        one vectorised finiteness test.

        Raises:
            PolicyMismatchError: another size than the policy observes (an env of another N
                or K than it serves).
            PolicyError: the observation holds NaN or infinity.
        """
        obs = np.asarray(obs)
        size = self.normalizer.mean.shape[0]
        if obs.ndim not in (1, 2) or obs.shape[-1] != size:
            m = self.manifest
            serves = (
                f"N={m.get('n_auvs')}, K up to {m.get('k_max')}"
                if self.general
                else f"N={m.get('n_auvs')}, K={m.get('n_nodes')}"
            )
            raise PolicyMismatchError(
                f"an observation of shape {obs.shape} for a policy that observes {size} entries "
                f"({serves}): accepted ({size},) or a batch (B, {size}), from an env of a "
                "scenario it serves"
            )
        if not np.isfinite(obs).all():
            raise PolicyError(
                "the observation holds NaN or infinity: accepted finite observations (an env "
                "whose state diverged must be reset)"
            )

    @property
    def general(self) -> bool:
        """A general policy (any K up to its K_max) observing tokens."""
        return self.manifest.get("policy") == "tokens"

    def __call__(self, env: Any, obs: np.ndarray) -> np.ndarray:
        """The action in a gymnasium env (`rollout.EnvPolicy`): the env's observation, or
        for a general policy the token observation of its mission."""
        if self.general:
            mission = env.unwrapped.mission
            return self.act(mission.observe_tokens(self.manifest["k_max"]))
        return self.act(obs)


def sha256(path: Path, cap_bytes: int = MAX_WEIGHTS_BYTES) -> str:
    """SHA-256 of a regular file of a policy folder, streamed (over `cap_bytes`: refused)."""
    return sha256_file(path, cap_bytes, PolicyFormatError)


def _sidecar(data: bytes) -> bytes:
    """The line `sha256sum` writes for policy.json."""
    return f"{hashlib.sha256(data).hexdigest()}  {MANIFEST}\n".encode()


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
        folder: the policy folder (absent, or a policy folder, which is replaced).
        policy: the SB3 actor-critic.
        normalization: `normalization_dict(venv)` of its VecNormalize.
        manifest: JSON-able metadata (env config, training config, evaluation...).
        extra_tensors: more tensors for the weights file (optimizer state, RNG states).

    Raises:
        PolicyError: `folder` is something else than a policy folder, or the write failed (the
            OS's reason: no space left, file too large, read-only...); the previous folder is
            kept and no `<folder>.tmp` is left.
    """
    _check_destination(folder)
    tensors = {f"policy.{k}": v.detach().cpu().contiguous() for k, v in policy.state_dict().items()}
    tensors.update(extra_tensors or {})
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
    }
    tmp = folder.with_name(folder.name + ".tmp")
    try:
        remove(tmp)
        tmp.mkdir(parents=True)
        save_file(tensors, tmp / WEIGHTS)
        write_new(tmp / NORMALIZATION, _json_bytes(normalization))
        full["files"] = {name: sha256(tmp / name) for name in (WEIGHTS, NORMALIZATION)}
        data = _json_bytes(full)
        write_new(tmp / MANIFEST, data)
        write_new(tmp / MANIFEST_SHA256, _sidecar(data))
        fsync_dir(tmp)
    except BaseException as exc:  # a fault or an interrupt: no half-written folder stays
        remove(tmp)
        if isinstance(exc, OSError):
            raise PolicyError(
                f"cannot write policy folder {folder}: {exc.strerror or exc}; the previous "
                "one (if any) is kept"
            ) from exc
        raise
    try:
        _swap_in(tmp, folder)
    except OSError as exc:  # the complete <folder>.tmp stays for `recover`
        raise PolicyError(f"cannot rename {tmp} to {folder}: {exc.strerror or exc}") from exc


def save_file(tensors: dict[str, torch.Tensor], path: Path) -> None:
    """The weights file, written by `write_new` (a fault raises the OSError with its reason;
    safetensors' own writer would raise a SafetensorError)."""
    write_new(path, tensor_bytes(tensors))


def _check_destination(folder: Path) -> None:
    """A policy folder replaces only a policy folder (or nothing): never a user's folder."""
    try:
        mode = os.lstat(folder).st_mode
    except FileNotFoundError:
        return
    if not stat.S_ISDIR(mode) or not os.path.lexists(folder / MANIFEST):
        raise PolicyError(
            f"{folder} exists and is not a policy folder: accepted a new path or a policy "
            "folder (which is replaced whole)"
        )


def _swap_in(tmp: Path, folder: Path) -> None:
    """`tmp` becomes `folder`; a kill between the renames leaves `<folder>.old` and the
    complete `tmp` (see `training.checkpoints.recover`)."""
    old = folder.with_name(folder.name + ".old")
    remove(old)
    if os.path.lexists(folder):
        folder.rename(old)
    tmp.rename(folder)
    fsync_dir(folder.parent)
    remove(old)


def _network(policy: ActorCriticPolicy) -> dict[str, Any]:
    """The manifest's description of the network (enough to rebuild it)."""
    if isinstance(policy, TokenPolicy):
        args = policy.token_args
        return {"policy": "tokens", "k_max": args["k_max"], "width": args["width"]}
    return {"policy": "mlp", "net_arch": policy.net_arch}


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


def read_manifest(folder: Path) -> dict[str, Any]:
    """policy.json, checked: its own checksum, format, schema version, the network's sizes
    (bounded before anything is built), and every other file's size and SHA-256.

    Raises:
        PolicyFormatError: saying which file is missing, unsafe, damaged or out of bounds.
    """
    path = folder / MANIFEST
    data = read_capped(path, MAX_JSON_BYTES, PolicyFormatError)
    sidecar = read_capped(folder / MANIFEST_SHA256, MAX_SIDECAR_BYTES, PolicyFormatError)
    match = _SIDECAR.fullmatch(sidecar.decode("ascii", "replace"))
    if match is None:
        raise PolicyFormatError(
            f"{folder / MANIFEST_SHA256} is not a checksum line: accepted "
            f"'<64 hex digits>  {MANIFEST}', as sha256sum writes it"
        )
    if hashlib.sha256(data).hexdigest() != match[1]:
        raise PolicyFormatError(
            f"{path} does not match its SHA-256 in {MANIFEST_SHA256}: the manifest was "
            "edited or damaged (a policy or checkpoint is used only as written)"
        )
    manifest = parse_json(data, path, PolicyFormatError)
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        raise PolicyFormatError(f"{path} is not an {FORMAT} manifest")
    if manifest.get("schema_version") != SCHEMA_VERSION:
        raise PolicyFormatError(
            f"{path}: schema_version {manifest.get('schema_version')!r}; accepted {SCHEMA_VERSION}"
        )
    check_network(manifest, str(path))
    files = manifest.get("files")
    if not isinstance(files, dict) or set(files) != {WEIGHTS, NORMALIZATION}:
        raise PolicyFormatError(
            f"{path}: 'files' must list {WEIGHTS} and {NORMALIZATION} with their SHA-256"
        )
    for name, cap in ((WEIGHTS, MAX_WEIGHTS_BYTES), (NORMALIZATION, MAX_JSON_BYTES)):
        if sha256(folder / name, cap) != files[name]:
            raise PolicyFormatError(
                f"{folder / name} does not match the SHA-256 in {MANIFEST}: the file is "
                "damaged or was changed"
            )
    return manifest


def _read_covered(folder: Path, name: str, manifest: dict[str, Any], cap_bytes: int) -> bytes:
    """A file's bytes, checked against its SHA-256 in the manifest (the very bytes used)."""
    data = read_capped(folder / name, cap_bytes, PolicyFormatError)
    if hashlib.sha256(data).hexdigest() != manifest["files"][name]:
        raise PolicyFormatError(
            f"{folder / name} does not match the SHA-256 in {MANIFEST}: the file is damaged or "
            "was changed"
        )
    return data


def read_tensors(folder: Path, manifest: dict[str, Any]) -> dict[str, torch.Tensor]:
    """Every tensor of the weights file (`manifest` from `read_manifest`), all finite."""
    data = _read_covered(folder, WEIGHTS, manifest, MAX_WEIGHTS_BYTES)
    try:
        tensors = load_tensors(data)
    except (SafetensorError, ValueError, RuntimeError) as exc:
        raise PolicyFormatError(
            f"{folder / WEIGHTS} is not a valid safetensors file: {exc}"
        ) from exc
    for key, value in tensors.items():
        if value.is_floating_point() and not bool(torch.isfinite(value).all()):
            raise PolicyFormatError(f"{folder / WEIGHTS}: tensor {key!r} holds non-finite values")
    return tensors


def _finite(value: Any, name: str, where: Path, positive: bool = False) -> float:
    ok = isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    if not ok or (positive and value <= 0):
        accepted = "a finite number > 0" if positive else "a finite number"
        raise PolicyFormatError(f"{where}: {name} is {value!r:.60}; accepted {accepted}")
    return float(value)


def read_normalization(folder: Path, manifest: dict[str, Any]) -> dict[str, Any]:
    """normalization.json, checked: its SHA-256, finite statistics (variances >= 0) with one
    entry per observation, and the return statistics when present."""
    path = folder / NORMALIZATION
    data = parse_json(
        _read_covered(folder, NORMALIZATION, manifest, MAX_JSON_BYTES), path, PolicyFormatError
    )
    if not isinstance(data, dict):
        raise PolicyFormatError(f"{path} is not a JSON object: accepted the keys obs_mean, ...")
    size = manifest["observation_size"]
    for key in ("obs_mean", "obs_var"):
        values = data.get(key)
        if not isinstance(values, list) or len(values) != size:
            raise PolicyFormatError(
                f"{path}: bad or missing field {key}: accepted a list of {size} numbers, one "
                f"per observation entry the policy observes"
            )
        for i, v in enumerate(values):
            _finite(v, f"{key}[{i}]", path)
    if min(data["obs_var"]) < 0:
        raise PolicyFormatError(f"{path}: obs_var holds a negative variance")
    for key in ("obs_count", "clip_obs", "epsilon"):
        if key not in data:
            raise PolicyFormatError(f"{path}: bad or missing field {key}")
        _finite(data[key], key, path, positive=key != "obs_count")
    for key in ("ret_mean", "ret_var", "ret_count", "clip_reward"):
        if key in data:
            _finite(data[key], key, path, positive=key == "clip_reward")
    return data


def read_normalizer(folder: Path, manifest: dict[str, Any]) -> Normalizer:
    """The observation normaliser of a policy folder (`read_normalization`)."""
    data = read_normalization(folder, manifest)
    return Normalizer(
        np.asarray(data["obs_mean"], dtype=np.float64),
        np.asarray(data["obs_var"], dtype=np.float64),
        float(data["obs_count"]),
        float(data["clip_obs"]),
        float(data["epsilon"]),
    )


def build_policy(manifest: dict[str, Any], tensors: dict[str, torch.Tensor]) -> ActorCriticPolicy:
    """The SB3 actor-critic of a manifest, with its weights (sizes bounded, shapes checked)."""
    check_network(manifest, "the manifest")
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
            # every parameter is loaded below: SB3's orthogonal init (QR, ~1 s) would be lost
            policy = ActorCriticPolicy(
                obs_space,
                act_space,
                lambda _: 0.0,
                net_arch=manifest.get("net_arch"),
                ortho_init=False,
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
    normalizer = read_normalizer(folder, manifest)
    policy = build_policy(manifest, read_tensors(folder, manifest))
    return LoadedPolicy(policy, normalizer, manifest)
