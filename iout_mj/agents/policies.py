"""Policies by name: the baselines, the shipped PPO policies, or a saved policy folder.

Every policy is a callable `policy(env, obs) -> action` (`rollout.EnvPolicy`). A trained
policy is read in the safe format (`policy_format`) and checked against the env it is asked
to fly: one trained for other spaces or another action mapping is refused with a message
naming the difference. A legacy SB3 folder (model.zip, vecnormalize.pkl) unpickles code and
loads only with `trust_pickle=True`.
"""

from __future__ import annotations

import pickle
import re
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3 import PPO

from iout_mj.agents.policy_format import (
    MANIFEST,
    LoadedPolicy,
    Normalizer,
    PolicyFormatError,
    load_policy_folder,
    normalization_dict,
    save_policy,
)
from iout_mj.agents.registry import POLICIES, make_policy
from iout_mj.agents.shield import DockShield, split_shield
from iout_mj.agents.shipped import SHIPPED_DIR, shipped_policies
from iout_mj.agents.team_policy import ACTION_DIMS, TeamPolicy, check_fit, team_observation_size
from iout_mj.config import Config
from iout_mj.envs.gym_env import ENV_ID
from iout_mj.errors import PolicyError, PolicyMismatchError

LEGACY_FILES = ("model.zip", "vecnormalize.pkl")
MAX_CANDIDATES = 1024
"""Candidate joint actions a rollout search may try per slot."""
ACTION_MAPPING = ("heading_levels", "speed_levels", "dtheta_max_deg", "dv_max_mps", "v_max_mps")
"""Motion settings that decide what an action index means: a policy needs the same."""


def resolve_policy_folder(name: str) -> Path:
    """The folder of a shipped policy name (e.g. 'ppo-n2-k7') or of a saved policy."""
    if (SHIPPED_DIR / name / MANIFEST).is_file():
        return SHIPPED_DIR / name
    path = Path(name)
    if path.is_dir():
        return path
    if path.is_file() and path.name in (MANIFEST, *LEGACY_FILES):
        return path.parent
    raise PolicyError(
        f"unknown policy {name!r}: accepted {', '.join(POLICIES)}, "
        f"a shipped policy {shipped_policies()}, or a policy folder"
    )


def check_fits(manifest: dict[str, Any], folder: Path, env: Any) -> None:
    """Refuse an env whose spaces or action mapping the policy cannot serve."""
    mission = env.unwrapped.mission
    obs_size, nvec = env.observation_space.shape[0], [int(v) for v in env.action_space.nvec]
    want_n, want_k = manifest.get("n_auvs"), manifest.get("n_nodes")
    if "team" in manifest:
        team = manifest["team"]
        check_team_sizes(team, manifest, folder)
        check_fit(mission.n_auvs, mission.n_nodes, team["n_max"], team["k_max"])
    elif manifest.get("policy") == "tokens":
        k_max = manifest.get("k_max", 0)
        if want_n != mission.n_auvs or mission.n_nodes > k_max:
            raise PolicyMismatchError(
                f"policy {folder} serves N={want_n} AUVs and up to {k_max} nodes; this env has "
                f"N={mission.n_auvs}, K={mission.n_nodes}"
            )
    elif (want_n, want_k) != (mission.n_auvs, mission.n_nodes) or (
        manifest.get("observation_size"),
        manifest.get("action_nvec"),
    ) != (obs_size, nvec):
        raise PolicyMismatchError(
            f"policy {folder} was trained for N={want_n}, K={want_k} (observation "
            f"{manifest.get('observation_size')}, actions {manifest.get('action_nvec')}); "
            f"this env has N={mission.n_auvs}, K={mission.n_nodes} (observation {obs_size}, "
            f"actions {nvec})"
        )
    trained = manifest.get("env_config", {}).get("motion", {})
    motion = env.unwrapped.cfg.motion
    for key in ACTION_MAPPING:
        if key in trained and trained[key] != getattr(motion, key):
            raise PolicyMismatchError(
                f"policy {folder} was trained with motion.{key}={trained[key]}; this env has "
                f"{getattr(motion, key)}: its action indices would mean other manoeuvres"
            )


def check_team_sizes(team: Any, manifest: dict[str, Any], folder: Path) -> None:
    """A team policy's manifest: its padded sizes and the network's observation and actions
    agree (`team_policy`)."""
    ok = isinstance(team, dict) and all(
        isinstance(team.get(key), int) and not isinstance(team.get(key), bool) and team[key] >= 1
        for key in ("n_max", "k_max")
    )
    if not ok:
        raise PolicyError(
            f"policy {folder}: team is {team!r:.80}; accepted {{algorithm, n_max, k_max}} with "
            "n_max and k_max integers >= 1"
        )
    size = team_observation_size(team["n_max"], team["k_max"])
    nvec = manifest.get("action_nvec", [])
    if (
        manifest.get("observation_size") != size
        or len(nvec) != ACTION_DIMS
        or nvec[2:] != [team["k_max"]] * 2
    ):
        raise PolicyError(
            f"policy {folder}: a team policy for n_max={team['n_max']}, k_max={team['k_max']} "
            f"observes {size} entries and chooses [heading, speed, k_max, k_max]; its manifest "
            f"says observation {manifest.get('observation_size')}, actions {nvec}"
        )


def _legacy(folder: Path, env: Any) -> LoadedPolicy:
    """An SB3 zip and a pickled VecNormalize: both can run code when read."""
    for name in LEGACY_FILES:
        if not (folder / name).is_file():
            raise PolicyError(
                f"{folder / name} is missing (the normalisation statistics are part of the policy)"
            )
    try:
        model: Any = PPO.load(folder / "model.zip", device="cpu")
        with (folder / "vecnormalize.pkl").open("rb") as f:
            stats = pickle.load(f)
    except Exception as exc:  # a zip from elsewhere, a truncated file, ...
        raise PolicyError(f"cannot load policy {folder}: {type(exc).__name__}: {exc}") from exc
    nvec = [int(v) for v in model.action_space.nvec]
    manifest = {
        "observation_size": int(model.observation_space.shape[0]),
        "action_nvec": nvec,
        "n_auvs": len(nvec) // 4,
        "n_nodes": nvec[2],
    }
    return LoadedPolicy(model.policy, Normalizer.from_vec_normalize(stats), manifest, stats)


PER_N_FAMILIES = ("ppo-general", "mappo")
"""Names that stand for one shipped policy per N: `<name>-n<N>` for the env's N (the general
token policies; the decentralised MAPPO team policies)."""


def for_n(name: str, n_auvs: int) -> str:
    """The policy `name` stands for in an env of `n_auvs` AUVs (see `PER_N_FAMILIES`)."""
    return f"{name}-n{n_auvs}" if name in PER_N_FAMILIES else name


def read_trained(name: str, env: Any, trust_pickle: bool = False) -> LoadedPolicy:
    """A trained policy by name or folder, checked against `env`."""
    name = for_n(name, env.unwrapped.mission.n_auvs)
    folder = resolve_policy_folder(name)
    if (folder / MANIFEST).is_file():
        try:
            loaded = load_policy_folder(folder)
        except PolicyFormatError as exc:
            raise PolicyError(f"cannot load policy {folder}: {exc}") from exc
    elif any((folder / f).is_file() for f in LEGACY_FILES):
        if not trust_pickle:
            raise PolicyError(
                f"{folder} is a legacy SB3 policy (model.zip / vecnormalize.pkl): loading it "
                "unpickles, which can run any code the file carries. Load it only if you trust "
                "its source, with --trust-pickle (trust_pickle=True)"
            )
        loaded = _legacy(folder, env)
    else:
        raise PolicyError(f"{folder} holds no policy: accepted a folder with {MANIFEST}")
    check_fits(loaded.manifest, folder, env)
    return loaded


SEARCH_SUFFIX = "+rollout"
"""`<trained policy>+rollout[C]`: the policy improved by decision-time rollouts (`search`)."""
DEFAULT_CANDIDATES = 16


def split_search(name: str) -> tuple[str, int | None]:
    """(the trained policy, candidates per slot) of `P+rollout[C]`; (name, None) otherwise."""
    found = re.fullmatch(rf"(.+){re.escape(SEARCH_SUFFIX)}([^/\\]*)", name, re.DOTALL)
    if found is None:
        return name, None
    base, count = found.groups()
    if not re.fullmatch("[0-9]*", count) or (count and not 1 <= int(count) <= MAX_CANDIDATES):
        raise PolicyError(
            f"policy {name!r}: accepted {base}{SEARCH_SUFFIX} ({DEFAULT_CANDIDATES} candidates "
            f"per slot) or {base}{SEARCH_SUFFIX}<C> with C from 1 to {MAX_CANDIDATES}"
        )
    return base, int(count) if count else DEFAULT_CANDIDATES


def load_policy(name: str, env: Any, seed: int = 0, trust_pickle: bool = False) -> Any:
    """A callable `policy(env, obs) -> action`: a baseline name or a trained policy (name or
    folder), checked against `env`; `P+rollout[C]` is P improved by rollouts (`search`),
    `P+dock` is P with the docking shield (`shield`)."""
    if not isinstance(name, str) or not name:
        raise PolicyError(
            f"policy {name!r}: accepted a name ({', '.join(POLICIES)}, a shipped policy "
            f"{shipped_policies()}) or a policy folder, as a non-empty string"
        )
    unshielded, shielded = split_shield(name)
    if shielded:
        return DockShield(load_policy(unshielded, env, seed, trust_pickle))
    base, candidates = split_search(name)
    if candidates is not None:
        from iout_mj.agents.search import RolloutSearch  # the batch: imported when searched

        loaded = read_trained(base, env, trust_pickle)
        if "team" in loaded.manifest:
            raise PolicyError(
                f"policy {name!r}: the rollout search improves a joint policy; {base} is a team "
                "policy (one actor per AUV): accepted it without +rollout"
            )
        try:
            return RolloutSearch(loaded, candidates, seed)
        except ValueError as exc:
            raise PolicyError(f"policy {name!r}: {exc}") from exc
    if name in POLICIES:
        baseline = make_policy(name, seed)

        def act(e: Any, _obs: np.ndarray) -> np.ndarray:
            return baseline(e.unwrapped.mission)

        act.reset = baseline.reset  # type: ignore[attr-defined]
        return act
    loaded = read_trained(name, env, trust_pickle)
    return TeamPolicy(loaded) if "team" in loaded.manifest else loaded


def convert_legacy(src: Path, dst: Path, env_config: Config, extra: dict[str, Any]) -> None:
    """Rewrite a trusted legacy SB3 policy folder in the safe format (same weights and
    statistics: the same actions)."""
    env: Any = gym.make(ENV_ID, backend="kinematic", config=env_config)
    loaded = _legacy(src, env)
    mission = env.unwrapped.mission
    manifest = {
        "n_auvs": mission.n_auvs,
        "n_nodes": mission.n_nodes,
        "env_config": env_config.to_dict(),
        **extra,
    }
    save_policy(dst, loaded.policy, normalization_dict(loaded.stats), manifest)
    env.close()
