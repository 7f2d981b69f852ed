"""PPO training (stable-baselines3) through the phases of a `TrainConfig`, with checkpoints,
held-out evaluation and `--resume` (same step count, learning-rate schedule and
normalisation statistics); what the run shows on the console and in TensorBoard is
`training.logs`."""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
import yaml
from stable_baselines3 import PPO
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.running_mean_std import RunningMeanStd
from stable_baselines3.common.vec_env import VecMonitor, VecNormalize
from tqdm import tqdm

from iout_mj.agents.policy_format import (
    MANIFEST,
    LoadedPolicy,
    Normalizer,
    write_atomic,
)
from iout_mj.agents.rollout import run_episode
from iout_mj.agents.token_policy import TokenPolicy
from iout_mj.config import Config
from iout_mj.envs import ENV_ID, KinematicVecEnv, PhysicsVecEnv, WarpVecEnv
from iout_mj.envs.scenario_vec_env import ScenarioVecEnv
from iout_mj.errors import CheckpointError
from iout_mj.mission.stats import episode_summary
from iout_mj.mission.tokens import K_MAX
from iout_mj.runtime import usable_cpus
from iout_mj.schema import ConfigError
from iout_mj.training import imitation
from iout_mj.training.callbacks import EvalCheckpointCallback, MissionLoggerCallback
from iout_mj.training.checkpoints import (
    Resumed,
    RunState,
    read_run_state,
    recover,
    restore,
    save_checkpoint,
)
from iout_mj.training.config import TrainConfig
from iout_mj.training.logs import (
    Console,
    eval_line,
    log_run_start,
    record_phase_start,
    run_logger,
)

HELD_OUT_SEED = 1_000_000
"""Evaluation seeds start here; training episodes draw theirs from the training seed."""


def scenario_env(cfg: TrainConfig, backend: str, n_nodes: int | None = None) -> Any:
    """The gymnasium env of the config's scenario, or of its held-out scenario with `n_nodes`
    nodes (the warp backend's scenes are evaluated on C MuJoCo: the same physics, one env)."""
    spec = cfg.env_spec if n_nodes is None else cfg.held_out_spec(n_nodes)
    return gym.make(ENV_ID, backend="mujoco" if backend == "warp" else backend, config=spec)


def make_env(cfg: TrainConfig, backend: str, seed: int) -> Any:
    """A monitored env for training (a picklable factory target)."""
    env = scenario_env(cfg, backend)
    env.reset(seed=seed)
    return Monitor(env)


def scenario_cells(cfg: TrainConfig, ks: list[int]) -> list[tuple[int, Config]]:
    """(K, env config) of every scenario cell a general policy trains on: each noise model
    with each K of `ks` (a phase's `TrainConfig.scenario_ks`, the imitation's `imitation_ks`)."""
    cells = []
    for noise in cfg.noise_models:
        env = dataclasses.replace(
            cfg.env,
            acoustics=dataclasses.replace(cfg.env.acoustics, noise_model=noise),
            scenario=dataclasses.replace(cfg.env.scenario, n_auvs=cfg.env_spec.n_auvs),
        )
        cells += [(k, env) for k in ks]
    return cells


def vec_env(
    cfg: TrainConfig, backend: str, n_envs: int, seed: int, parallel: bool, phase: int | None = None
) -> Any:
    """The training VecEnv of a phase: one batch of `n_envs` environments in this process (with
    tokens, `n_envs` per scenario cell of `phase`), for either backend; with `parallel`, the
    MuJoCo scenes step on one thread per core (the batch's rollout threads; with tokens, the
    cells concurrently)."""
    if cfg.policy == "tokens":  # the cells step concurrently, one thread per core
        threads = usable_cpus() if parallel and backend == "mujoco" else 0
        cells = scenario_cells(cfg, cfg.scenario_ks(phase))
        return VecMonitor(ScenarioVecEnv(cells, n_envs, backend, seed, threads))
    threads = min(n_envs, usable_cpus()) if parallel and backend == "mujoco" else 0
    kinds = {"kinematic": KinematicVecEnv, "mujoco": PhysicsVecEnv, "warp": WarpVecEnv}
    return VecMonitor(kinds[backend](n_envs, config=cfg.env_spec, seed=seed, nthread=threads))


def torch_setup(cfg: TrainConfig) -> None:
    """This process's torch for training `cfg`: its thread count, and no argument checks in
    the action distributions (SB3 builds them from logits that are valid by construction; the
    checks cost ~9 % of the general recipe's PPO time)."""
    torch.set_num_threads(cfg.torch_threads)
    torch.distributions.Distribution.set_default_validate_args(False)


def network(cfg: TrainConfig) -> dict[str, Any]:
    """What a policy manifest says of the network of `cfg`."""
    if cfg.policy == "tokens":
        return {"policy": "tokens", "k_max": K_MAX, "width": cfg.width}
    return {"policy": "mlp", "net_arch": list(cfg.net_arch)}


def _lr_schedule(cfg: TrainConfig) -> Any:
    start, end = cfg.learning_rate, cfg.learning_rate_final

    def schedule(progress_remaining: float) -> float:
        return end + (start - end) * progress_remaining

    return schedule


def evaluate_model(
    model: Any, stats: Any, cfg: TrainConfig, backend: str, seed: int = HELD_OUT_SEED
) -> dict[str, float]:
    """Deterministic episodes on held-out seeds (their K: `TrainConfig.eval_ks`): the mean
    episode summary and return."""
    loaded = LoadedPolicy(model.policy, Normalizer.from_vec_normalize(stats), network(cfg))
    rows = []
    for e, k in enumerate(cfg.eval_ks()):
        env = scenario_env(cfg, backend, k)
        metrics = run_episode(env, loaded, seed + e)
        env.close()
        rows.append({"return": metrics["return"], **episode_summary(metrics)})
    return {k: float(np.mean([r[k] for r in rows])) for k in rows[0]}


def selection_score(metrics: dict[str, float]) -> float:
    """Model selection: docking in at least 95 % of the held-out episodes first (each point
    short costs 100 slots), then low AoI over the whole horizon (so that docking early, which
    shortens the averaging window of the mission mean, does not pay)."""
    return -metrics["mean_aoi_horizon"] - 100.0 * max(0.0, 0.95 - metrics["docking_rate"])


def new_model(cfg: TrainConfig, venv: Any, device: str = "cpu") -> Any:
    """A fresh PPO with the config's hyperparameters on `venv` (torch on `device`)."""
    if cfg.policy == "tokens":
        policy: Any = TokenPolicy
        kwargs: dict[str, Any] = {"k_max": K_MAX, "width": cfg.width}
    else:
        policy, kwargs = "MlpPolicy", {"net_arch": list(cfg.net_arch)}
    return PPO(
        policy,
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
        device=device,
        verbose=0,
        policy_kwargs=kwargs,
    )


def warm_start(model: Any, cfg: TrainConfig, progress: bool) -> list[str]:
    """DAgger from the config's planner (`training.imitation`) on its scenario cells; the
    return statistics of the planner's episodes become the VecNormalize's. With `progress`,
    a bar of the episodes flown (its round and fitting epoch beside it) and a line per round;
    returns those lines."""
    im = cfg.imitation
    assert im is not None
    rng = np.random.RandomState(cfg.seed)
    torch.manual_seed(cfg.seed)
    cells = scenario_cells(cfg, cfg.imitation_ks())
    data = imitation.Demonstrations()
    epochs, beta, lines = im.epochs, im.beta, []
    bar = tqdm(
        total=im.total_episodes,
        unit="episode",
        desc=f"{cfg.name} imitation (DAgger)",
        disable=not progress,
    )

    def learner(tokens: np.ndarray) -> np.ndarray:
        action, _ = model.policy.predict(tokens, deterministic=True)
        return action

    def fitting(r: int, epochs: int) -> Any:
        return lambda e: bar.set_postfix_str(f"round {r}/{im.rounds}: fitting, epoch {e}/{epochs}")

    with bar:
        bar.set_postfix_str(f"round 0/{im.rounds}: the planner flies")
        imitation.fly(cells, im.episodes, rng, None, 1.0, im.teacher, data, bar.update)
        for r in range(im.rounds + 1):
            acc, nll, rms = imitation.fit(
                model.policy,
                data,
                cfg.gamma,
                epochs,
                im.learning_rate,
                rng,
                epoch_done=fitting(r, epochs),
            )
            lines.append(
                f"imitation round {r}/{im.rounds}: {len(data.obs):,} states, accuracy "
                f"(heading, speed, AET node, uplink node) {np.round(acc, 3).tolist()}, "
                f"nll {nll:.3f}"
            )
            if progress:
                bar.write(lines[-1])
            if r < im.rounds:
                bar.set_postfix_str(
                    f"round {r + 1}/{im.rounds}: the policy flies (the planner at p={beta:.3g})"
                )
                imitation.fly(
                    cells, im.round_episodes, rng, learner, beta, im.teacher, data, bar.update
                )
                epochs, beta = im.round_epochs, beta / 2
    model.get_vec_normalize_env().ret_rms = rms
    return lines


TENSORBOARD_DIR = "tb/ppo_0"
"""The run's TensorBoard events, in its folder (`tensorboard --logdir <run>/tb`)."""
RUN_FILES = (
    "config.yaml",
    "state.json",
    "last",
    "best",
    "last.tmp",
    "last.old",
    "best.tmp",
    "tb",
)


def _start(cfg: TrainConfig, out: Path, resume: bool, overwrite: bool) -> None:
    """Check the run folder: a run to resume, or a folder free for a new run."""
    if resume:
        recover(out / "last")
        recover(out / "best")
        if not (out / "last" / MANIFEST).is_file():
            raise CheckpointError(f"nothing to resume in {out}: no complete last/ checkpoint")
        if TrainConfig.load(out / "config.yaml") != cfg:
            raise ConfigError(f"--resume with a different config than {out / 'config.yaml'}")
        return
    existing = [name for name in RUN_FILES if (out / name).exists()]
    if existing and not overwrite:
        raise CheckpointError(
            f"{out} already holds a run ({', '.join(existing)}): use --resume to continue it, "
            "--overwrite to start again, or another --out"
        )
    for name in existing:
        path = out / name
        shutil.rmtree(path) if path.is_dir() else path.unlink()
    try:
        out.mkdir(parents=True, exist_ok=True)
        write_atomic(out / "config.yaml", yaml.safe_dump(cfg.to_dict(), sort_keys=False).encode())
    except OSError as exc:
        raise CheckpointError(f"cannot write {out / 'config.yaml'}: {exc.strerror or exc}") from exc


def phase_model(model: Any, cfg: TrainConfig, venv: Any) -> Any:
    """The model of a phase on `venv`: new for the first phase (or to be restored from a
    checkpoint), else the previous phase's model and statistics on the new backend."""
    # token features are scaled already (and padded with a mask): not normalised
    norm_obs = cfg.policy == "mlp"
    normalized = VecNormalize(venv, norm_obs=norm_obs, norm_reward=True, gamma=cfg.gamma)
    if not norm_obs:  # the identity transform, saved with the policy like any statistics
        normalized.obs_rms = RunningMeanStd(shape=venv.observation_space.shape)  # type: ignore[assignment]
    if model is None:
        return new_model(cfg, normalized)
    stats = model.get_vec_normalize_env()
    normalized.obs_rms, normalized.ret_rms = stats.obs_rms, stats.ret_rms
    stats.close()
    model.set_env(normalized)
    return model


def train(
    cfg: TrainConfig,
    out: Path,
    resume: bool = False,
    progress: bool = True,
    parallel: bool = True,
    overwrite: bool = False,
) -> RunState:
    """Train PPO through every phase; checkpoints in `out` (see `training.checkpoints`), the
    TensorBoard log in `out / TENSORBOARD_DIR`; with `progress`, a progress bar through the
    imitation and each phase and a line per held-out evaluation (`run_summary` sums the run
    up)."""
    torch_setup(cfg)
    _start(cfg, out, resume, overwrite)
    # the run state is the checkpoint's own on resume
    state = read_run_state(out / "last", cfg) if resume else RunState()
    console = Console(cfg, progress)
    try:
        _train(cfg, out, state, resume, parallel, console)
    finally:
        console.close()
    return state


def _train(
    cfg: TrainConfig, out: Path, state: RunState, resume: bool, parallel: bool, console: Console
) -> None:
    model: Any = None
    logger: Logger | None = None
    resumed: Resumed | None = None
    phase_start = sum(p.timesteps for p in cfg.phases[: state.phase])
    index = state.phase

    def checkpoint(model: Any) -> None:
        """Evaluate; log it (TensorBoard first, see `logs.run_logger`), then save."""
        backend = cfg.phases[index].backend
        metrics = evaluate_model(model, model.get_vec_normalize_env(), cfg, backend)
        state.num_timesteps = model.num_timesteps
        entry = {
            "num_timesteps": model.num_timesteps,
            "phase": index + 1,
            "phases": len(cfg.phases),
            "backend": backend,
        }
        entry.update(metrics)
        state.history.append(entry)
        score = selection_score(metrics)
        for k, v in metrics.items():
            model.logger.record(f"eval/{k}", v)
        model.logger.dump(model.num_timesteps)
        console.line(eval_line(entry, score > state.best_score))
        extra = {"eval": entry, "env_phase": index}
        if score > state.best_score:
            state.best_score = score
            save_checkpoint(model, out / "best", cfg, state, extra)
        # inside a phase whose environments run, --resume continues their episodes
        live = state.phase == index and model._last_obs is not None
        save_checkpoint(model, out / "last", cfg, state, extra, live)
        state.save(out / "state.json")

    try:
        for index in range(state.phase, len(cfg.phases)):
            phase = cfg.phases[index]
            phase_end = phase_start + phase.timesteps
            seed = cfg.seed * 1000 + index * 100
            venv = vec_env(cfg, phase.backend, cfg.n_envs, seed, parallel, index)
            first = model is None
            model = phase_model(model, cfg, venv)
            if first and resume:
                resumed = restore(model, out / "last")  # mid-phase: the running episodes too
                if not resumed.live and index > 0:
                    # a later phase's environments start from their seed, as in an
                    # uninterrupted run (PPO's constructor must not reseed them)
                    venv.unwrapped.set_random_state(np.random.RandomState(seed))
            if first:
                logger = run_logger(out / TENSORBOARD_DIR, model.num_timesteps + 1 if resume else 0)
                model.set_logger(logger)
                if resume:
                    logger.record("run/resumed", f"resumed at step {model.num_timesteps:,}")
                else:
                    log_run_start(logger, cfg)
                    if cfg.imitation is not None:
                        lines = warm_start(model, cfg, console.enabled)
                        logger.record("run/imitation", "\n\n".join(lines))
                        checkpoint(model)
            assert logger is not None
            if not (first and resumed is not None and resumed.live):  # the phase starts
                record_phase_start(logger, cfg, index, model.num_timesteps)
            console.phase(index, model.num_timesteps)
            if phase_end - model.num_timesteps > 0:
                callbacks = [
                    MissionLoggerCallback(model.num_timesteps, phase=index + 1),
                    EvalCheckpointCallback(
                        cfg.eval_every_steps,
                        phase_end,
                        model.num_timesteps,
                        checkpoint,
                        console.steps,
                    ),
                ]
                # SB3 counts the schedule over num_timesteps / (num_timesteps + remaining);
                # the total must span all phases, so learn() is told the overall end (the
                # callback ends the phase).
                model.learn(
                    total_timesteps=cfg.total_timesteps - model.num_timesteps,
                    reset_num_timesteps=False,
                    callback=callbacks,
                    progress_bar=False,
                )
            state.phase = index + 1
            checkpoint(model)
            phase_start = phase_end
    finally:
        if logger is not None:
            logger.close()
        if model is not None:
            model.get_env().close()


def _phase_of(entry: dict[str, Any]) -> str:
    """The phase of a history entry as "1 of 2 (kinematic)" (the backend alone for an entry
    of a run begun before entries named their phase from 1)."""
    if "phases" not in entry:
        return str(entry["backend"])
    return f"{entry['phase']} of {entry['phases']} ({entry['backend']})"


def run_summary(cfg: TrainConfig, out: Path, state: RunState) -> dict[str, Any]:
    """What a finished run hands its researcher: the best checkpoint (the one model selection
    kept: its folder, step, phase and evaluation) and the last, with the phases done."""
    described = {"num_timesteps", "phase", "phases", "backend"}

    def checkpoint(folder: str, entry: dict[str, Any]) -> dict[str, Any]:
        return {
            "checkpoint": str(out / folder),
            "num_timesteps": entry["num_timesteps"],
            "phase": _phase_of(entry),
            "eval": {k: v for k, v in entry.items() if k not in described},
        }

    summary: dict[str, Any] = {
        "out": str(out),
        "num_timesteps": state.num_timesteps,
        "phases_done": f"{state.phase} of {len(cfg.phases)}",
    }
    if state.history:
        scores = [selection_score(e) for e in state.history]
        best = state.history[scores.index(max(scores))]  # the first best, as training kept it
        summary["best"] = checkpoint("best", best)
        summary["last"] = checkpoint("last", state.history[-1])
    return summary
