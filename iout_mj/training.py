"""PPO training (stable-baselines3): YAML configs, phases, checkpoints, resume, evaluation.

A run folder holds `config.yaml` (the exact config), `last/` and `best/` (each: `model.zip`,
`vecnormalize.pkl`, `meta.json`), `state.json` (phase and step count) and TensorBoard logs
under `tb/`. `--resume` continues from `last/` with the same step count, learning-rate
schedule and normalisation statistics.
"""

from __future__ import annotations

import json
import shutil
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from iout_mj.config import ConfigError, _build

HELD_OUT_SEED = 1_000_000
"""Evaluation seeds start here; training episodes draw theirs from the training seed."""


@dataclass(frozen=True)
class PhaseConfig:
    """One training phase on one backend."""

    backend: str = "mujoco"
    timesteps: int = 100_000

    def __post_init__(self) -> None:
        if self.backend not in ("mujoco", "kinematic"):
            raise ConfigError(f"phase backend={self.backend!r}: accepted 'mujoco' or 'kinematic'")
        if self.timesteps < 1:
            raise ConfigError(f"phase timesteps={self.timesteps}: accepted an integer >= 1")


@dataclass(frozen=True)
class TrainConfig:
    """Hyperparameters (rl-zoo style), keyed by scenario; the defaults are those of the
    shipped configs in training/configs."""

    name: str = "ppo"
    n_auvs: int = 2
    n_nodes: int = 7
    layout: str = "paper"
    phases: tuple[PhaseConfig, ...] = (PhaseConfig(),)
    n_envs: int = 8
    n_steps: int = 512
    batch_size: int = 512
    n_epochs: int = 10
    learning_rate: float = 3e-4
    learning_rate_final: float = 3e-5
    """The learning rate falls linearly to this over all phases."""
    ent_coef: float = 0.01
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    net_arch: tuple[int, ...] = (256, 256)
    seed: int = 0
    eval_every_steps: int = 20_000
    eval_episodes: int = 10
    torch_threads: int = 1

    def __post_init__(self) -> None:
        if self.n_envs < 1 or self.n_steps < 1 or self.batch_size < 1:
            raise ConfigError("n_envs, n_steps and batch_size: accepted integers >= 1")
        if (self.n_envs * self.n_steps) % self.batch_size:
            raise ConfigError(
                f"batch_size={self.batch_size} must divide n_envs*n_steps="
                f"{self.n_envs * self.n_steps}"
            )
        if not self.phases:
            raise ConfigError("phases: accepted a non-empty list of {backend, timesteps}")

    @property
    def total_timesteps(self) -> int:
        return sum(p.timesteps for p in self.phases)

    @classmethod
    def load(cls, path: str | Path) -> TrainConfig:
        path = Path(path)
        if not path.is_file():
            raise ConfigError(f"training config {path} does not exist")
        try:
            data = yaml.safe_load(path.read_text()) or {}
        except yaml.YAMLError as exc:
            raise ConfigError(f"training config {path} is not valid YAML: {exc}") from exc
        return _build(cls, data, path.stem)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["phases"] = [dict(p) for p in d["phases"]]
        d["net_arch"] = list(self.net_arch)
        return d


def scenario_env(cfg: TrainConfig, backend: str) -> Any:
    """The gymnasium env of the config's scenario."""
    import gymnasium as gym

    import iout_mj  # noqa: F401  (registers the env, also in a fresh worker process)

    return gym.make(
        "iout_mj/MultiAUV-v0",
        n_auvs=cfg.n_auvs,
        n_nodes=cfg.n_nodes,
        backend=backend,
        layout=cfg.layout,
    )


def make_env(cfg: TrainConfig, backend: str, seed: int) -> Any:
    """A monitored env for training (a picklable factory target)."""
    from stable_baselines3.common.monitor import Monitor

    env = scenario_env(cfg, backend)
    env.reset(seed=seed)
    return Monitor(env)


def vec_env(cfg: TrainConfig, backend: str, n_envs: int, seed: int, parallel: bool) -> Any:
    """The training VecEnv: one batch of `n_envs` environments in this process, for either
    backend (`vec_env.KinematicVecEnv` / `PhysicsVecEnv`); with `parallel`, the MuJoCo
    rollout runs on one C thread per core."""
    import os

    from stable_baselines3.common.vec_env import VecMonitor

    from iout_mj.vec_env import KinematicVecEnv, PhysicsVecEnv

    args = (n_envs, cfg.n_auvs, cfg.n_nodes, cfg.layout)
    if backend == "kinematic":
        return VecMonitor(KinematicVecEnv(*args, seed=seed))
    threads = min(n_envs, os.cpu_count() or 1) if parallel else 0
    return VecMonitor(PhysicsVecEnv(*args, seed=seed, nthread=threads))


@dataclass
class RunState:
    phase: int = 0
    num_timesteps: int = 0
    best_score: float = -np.inf
    history: list[dict[str, Any]] = field(default_factory=list)


def _save_checkpoint(
    model: Any, venv: Any, folder: Path, cfg: TrainConfig, extra: dict[str, Any]
) -> None:
    tmp = folder.with_name(folder.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    model.save(tmp / "model.zip")
    venv.save(str(tmp / "vecnormalize.pkl"))
    meta = {"n_auvs": cfg.n_auvs, "n_nodes": cfg.n_nodes, "config": cfg.to_dict(), **extra}
    (tmp / "meta.json").write_text(json.dumps(meta, indent=2) + "\n")
    shutil.rmtree(folder, ignore_errors=True)
    tmp.rename(folder)  # a checkpoint is replaced whole or not at all


def _lr_schedule(cfg: TrainConfig) -> Any:
    start, end = cfg.learning_rate, cfg.learning_rate_final

    def schedule(progress_remaining: float) -> float:
        return end + (start - end) * progress_remaining

    return schedule


def evaluate_policy_metrics(
    model: Any,
    venv_stats: Any,
    cfg: TrainConfig,
    backend: str,
    episodes: int,
    seed: int = HELD_OUT_SEED,
) -> dict[str, float]:
    """Deterministic episodes on held-out seeds; mean metrics and return."""
    env = scenario_env(cfg, backend)
    rows = []
    for e in range(episodes):
        obs, _ = env.reset(seed=seed + e)
        ret = 0.0
        while True:
            action, _ = model.predict(venv_stats.normalize_obs(obs), deterministic=True)
            obs, r, term, trunc, info = env.step(action)
            ret += float(r)
            if term or trunc:
                m = info["metrics"]
                rows.append(
                    {
                        "return": ret,
                        "mean_aoi": m["mean_aoi"],
                        "mean_aoi_horizon": m["mean_aoi_horizon"],
                        "jain": m["jain"],
                        "delivered_mbit": m["delivered_bits"] / 1e6,
                        "docked": float(all(m["docked"])),
                        "energy_kj": float(np.mean(m["propulsion_energy_j"])) / 1e3,
                    }
                )
                break
    env.close()
    return {k: float(np.mean([r[k] for r in rows])) for k in rows[0]}


def _score(metrics: dict[str, float]) -> float:
    """Model selection: docking first, then low AoI over the whole horizon (so that docking
    early, which shortens the averaging window of the mission mean, does not pay)."""
    return -metrics["mean_aoi_horizon"] - 100.0 * max(0.0, 0.95 - metrics["docked"])


def new_model(cfg: TrainConfig, venv: Any, tensorboard: Path | None = None) -> Any:
    """A fresh PPO with the config's hyperparameters on `venv`."""
    from stable_baselines3 import PPO

    return PPO(
        "MlpPolicy",
        venv,
        learning_rate=_lr_schedule(cfg),
        n_steps=cfg.n_steps,
        batch_size=cfg.batch_size,
        n_epochs=cfg.n_epochs,
        gamma=cfg.gamma,
        gae_lambda=cfg.gae_lambda,
        clip_range=cfg.clip_range,
        ent_coef=cfg.ent_coef,
        seed=cfg.seed,
        device="cpu",
        verbose=0,
        policy_kwargs={"net_arch": list(cfg.net_arch)},
        tensorboard_log=None if tensorboard is None else str(tensorboard),
    )


def train(
    cfg: TrainConfig, out: Path, resume: bool = False, progress: bool = True, parallel: bool = True
) -> RunState:
    """Train PPO through every phase; checkpoints in `out`."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import VecNormalize
    from tqdm import tqdm

    torch.set_num_threads(cfg.torch_threads)
    out.mkdir(parents=True, exist_ok=True)
    state_path = out / "state.json"
    if resume:
        if not (state_path.is_file() and (out / "last" / "model.zip").is_file()):
            raise FileNotFoundError(f"nothing to resume in {out}: no last/ checkpoint")
        saved = TrainConfig.load(out / "config.yaml")
        if saved != cfg:
            raise ConfigError(f"--resume with a different config than {out / 'config.yaml'}")
        state = RunState(**json.loads(state_path.read_text()))
    else:
        if (out / "last").exists():
            raise FileExistsError(f"{out} already holds a run: use --resume, or another --out")
        (out / "config.yaml").write_text(yaml.safe_dump(cfg.to_dict(), sort_keys=False))
        state = RunState()

    bar = tqdm(
        total=cfg.total_timesteps,
        initial=state.num_timesteps,
        unit="step",
        desc=cfg.name,
        disable=not progress,
    )
    phase_start = sum(p.timesteps for p in cfg.phases[: state.phase])

    class Monitor(BaseCallback):
        """TensorBoard: reward terms and episode metrics; periodic evaluation and checkpoints."""

        def __init__(self, phase_end: int) -> None:
            super().__init__()
            self.phase_end = phase_end
            self.last_eval = state.num_timesteps
            self.t0 = time.perf_counter()
            self.n0 = state.num_timesteps

        def _on_step(self) -> bool:
            batch = getattr(self.training_env.unwrapped, "mission", None)  # KinematicVecEnv
            if batch is not None:
                for k, v in batch.terms.items():
                    self.logger.record_mean(f"reward/{k}", float(np.mean(v)))
            for info in self.locals["infos"]:
                for k, v in info.get("reward_terms", {}).items():
                    self.logger.record_mean(f"reward/{k}", v)
                m = info.get("metrics")
                if m is not None:
                    self.logger.record_mean("episode/mean_aoi", m["mean_aoi"])
                    self.logger.record_mean("episode/jain", m["jain"])
                    self.logger.record_mean("episode/delivered_mbit", m["delivered_bits"] / 1e6)
                    self.logger.record_mean(
                        "episode/energy_kj", float(np.mean(m["propulsion_energy_j"])) / 1e3
                    )
                    self.logger.record_mean("episode/docking_rate", float(all(m["docked"])))
            bar.update(self.model.num_timesteps - bar.n)
            if self.model.num_timesteps - self.last_eval >= cfg.eval_every_steps:
                self.last_eval = self.model.num_timesteps
                checkpoint(self.model, backend)
            return self.model.num_timesteps < self.phase_end

        def _on_rollout_end(self) -> None:
            dt = time.perf_counter() - self.t0
            self.logger.record("time/fps_run", (self.model.num_timesteps - self.n0) / max(dt, 1e-9))

    def checkpoint(model: Any, backend: str) -> None:
        metrics = evaluate_policy_metrics(model, venv, cfg, backend, cfg.eval_episodes)
        if getattr(model, "_logger", None) is not None:  # absent until learn() ran
            for k, v in metrics.items():
                model.logger.record(f"eval/{k}", v)
        state.num_timesteps = model.num_timesteps
        entry = {
            "num_timesteps": model.num_timesteps,
            "phase": state.phase,
            "backend": backend,
            **metrics,
        }
        state.history.append(entry)
        score = _score(metrics)
        if score > state.best_score:
            state.best_score = score
            _save_checkpoint(model, venv, out / "best", cfg, {"eval": entry})
        _save_checkpoint(model, venv, out / "last", cfg, {"eval": entry})
        state_path.write_text(json.dumps(asdict(state), indent=1) + "\n")

    model = None
    venv = None
    for index in range(state.phase, len(cfg.phases)):
        phase = cfg.phases[index]
        backend = phase.backend
        phase_end = phase_start + phase.timesteps
        venv = vec_env(cfg, backend, cfg.n_envs, cfg.seed * 1000 + index * 100, parallel)
        if model is None and (resume or index > 0) and (out / "last").exists():
            venv = VecNormalize.load(str(out / "last" / "vecnormalize.pkl"), venv)
            model = PPO.load(
                out / "last" / "model.zip",
                env=venv,
                device="cpu",
                custom_objects={
                    "learning_rate": _lr_schedule(cfg),
                    "lr_schedule": _lr_schedule(cfg),
                },
            )
        elif model is None:
            venv = VecNormalize(venv, norm_obs=True, norm_reward=True, gamma=cfg.gamma)
            model = new_model(cfg, venv, out / "tb")
        else:  # next phase: same model and statistics, new backend
            stats = model.get_vec_normalize_env()
            assert stats is not None  # every model here is trained under VecNormalize
            new = VecNormalize(venv, norm_obs=True, norm_reward=True, gamma=cfg.gamma)
            new.obs_rms, new.ret_rms = stats.obs_rms, stats.ret_rms
            stats.close()
            venv = new
            model.set_env(venv)
        remaining = phase_end - model.num_timesteps
        if remaining > 0:
            # SB3 counts the schedule over num_timesteps / (num_timesteps + remaining); the
            # total must span all phases, so learn() is told the overall end.
            model.learn(
                total_timesteps=cfg.total_timesteps - model.num_timesteps,
                reset_num_timesteps=False,
                callback=Monitor(phase_end),
                tb_log_name="ppo",
                progress_bar=False,
            )  # the callback ends the phase
        state.phase = index + 1
        checkpoint(model, backend)
        phase_start = phase_end
    bar.close()
    if venv is not None:
        venv.close()
    return state


def load_for_env(path: Path, env: Any) -> Any:
    """A `policy(env, obs) -> action` from a saved run folder's model.zip, checked against env."""
    from stable_baselines3 import PPO

    folder = path.parent
    meta_path = folder / "meta.json"
    try:
        model = PPO.load(path, device="cpu")
    except Exception as exc:  # a zip from elsewhere, a truncated file, ...
        raise ValueError(f"cannot load policy {path}: {type(exc).__name__}: {exc}") from exc
    mission = env.unwrapped.mission
    meta = json.loads(meta_path.read_text()) if meta_path.is_file() else {}
    want = (meta.get("n_auvs"), meta.get("n_nodes"))
    if model.action_space.shape != env.action_space.shape or (
        want != (None, None) and want != (mission.n_auvs, mission.n_nodes)
    ):
        raise ValueError(
            f"policy {path} was trained for N={want[0]}, K={want[1]} "
            f"(action space {model.action_space}); this env has "
            f"N={mission.n_auvs}, K={mission.n_nodes}"
        )
    stats_path = folder / "vecnormalize.pkl"
    stats = None
    if stats_path.is_file():
        import pickle

        with stats_path.open("rb") as f:
            stats = pickle.load(f)

    def act(_env: Any, obs: np.ndarray) -> np.ndarray:
        x = stats.normalize_obs(obs) if stats is not None else obs
        action, _ = model.predict(x, deterministic=True)
        return action

    return act
