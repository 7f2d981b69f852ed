"""The training configuration: PPO hyperparameters and phases, one YAML per scenario."""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from iout_mj.config import MAX_NODES, MIN_NODES, Config, files_from_folder
from iout_mj.scenarios import EnvSpec, resolve
from iout_mj.schema import (
    ConfigError,
    build_dataclass,
    check_finite,
    check_types,
    in_range,
    load_layered,
    require,
)

BACKENDS = ("mujoco", "kinematic", "warp")
NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")
MAX_TIMESTEPS = 10**10
"""Environment steps of a phase (and between evaluations)."""
MAX_ROLLOUT_STEPS = 1 << 18
"""Transitions of one PPO rollout (envs x n_steps): the buffer holds an observation of up to
~500 float32 each, so it stays under ~0.5 GB."""
MAX_IMITATION_SLOTS = 250_000
"""Slots the DAgger data set records ((episodes + rounds x round_episodes) x horizon_slots):
a token observation of up to ~4 kB each, so it stays under ~1 GB."""
MAX_ENVS = 1024
MAX_LAYERS, MAX_WIDTH = 8, 2048
"""net_arch: at most 8 layers of 2048 (33M parameters, 0.4 GB with Adam's moments)."""


def env_files_from_folder(data: dict[str, Any], folder: Path) -> dict[str, Any]:
    """A training config's data with its env's relative file paths made absolute from `folder`
    (the file's)."""
    if not isinstance(data.get("env"), dict):
        return data
    return {**data, "env": files_from_folder(data["env"], folder)}


def check_run_config(config: Any) -> None:
    """A training config's shared checks: every field's type and finiteness, and a name that
    can be a run folder's."""
    check_types(config)
    check_finite(config)
    require(bool(NAME.fullmatch(config.name)), "name", config.name, "letters, digits, - _ .")


def require_node_range(
    node_range: tuple[int, int], alternative: str = "", name: str = "node_range"
) -> None:
    """A range of K (the field `name`): [low, high] within the nodes a config allows."""
    lo, hi = node_range
    require(
        MIN_NODES <= lo <= hi <= MAX_NODES,
        name,
        list(node_range),
        f"[low, high] with {MIN_NODES} <= low <= high <= {MAX_NODES}{alternative}",
    )


@dataclass(frozen=True)
class PhaseConfig:
    """One training phase on one backend."""

    backend: str = "mujoco"
    timesteps: int = 100_000
    node_range: tuple[int, int] | None = None
    """A curriculum over K (token policies): this phase's scenario cells keep their number,
    their K spread evenly over [low, high] (`scenario_ks`); None: the config's node_range."""

    def __post_init__(self) -> None:
        check_types(self)
        require(self.backend in BACKENDS, "backend", self.backend, f"one of {BACKENDS}")
        in_range(self, "timesteps", 1, MAX_TIMESTEPS)
        if self.node_range is not None:
            require_node_range(self.node_range, ", or null")


POLICIES = ("mlp", "tokens")
NOISE_MODELS = ("flat", "wenz")


@dataclass(frozen=True)
class ImitationConfig:
    """Warm start of a policy by DAgger from a planner (`training.imitation` for the general
    policies, `training.marl_imitation` for team policies)."""

    planner: str = "tour-scheduler"
    episodes: int = 300
    """Episodes the planner flies first."""
    epochs: int = 30
    rounds: int = 3
    """DAgger rounds after the first fit: the policy flies, the planner labels."""
    round_episodes: int = 150
    round_epochs: int = 15
    beta: float = 0.5
    """Probability that the planner acts in DAgger round 1; it halves every round."""
    learning_rate: float = 1e-3
    teacher_dock_spare_slots: float | None = None
    """Slots the teacher keeps in hand when heading into the dock (tour-scheduler and
    solver-tour; null: the planner's own), so that a pupil's timing errors still dock."""
    node_range: tuple[int, int] | None = None
    """tokens: the K of the cells flown, spread over [low, high] as a phase's `node_range`
    (the same number of cells); null: the config's node_range. Team policies: null."""

    def __post_init__(self) -> None:
        from iout_mj.agents.planners import TourScheduler
        from iout_mj.agents.registry import POLICIES as PLANNERS

        check_types(self)
        check_finite(self)
        require(self.planner in PLANNERS, "planner", self.planner, f"one of {sorted(PLANNERS)}")
        if self.teacher_dock_spare_slots is not None:
            tours = sorted(k for k, v in PLANNERS.items() if issubclass(v, TourScheduler))
            require(
                self.planner in tours,
                "planner",
                self.planner,
                f"one of {tours} with teacher_dock_spare_slots",
            )
            in_range(self, "teacher_dock_spare_slots", 0.0, 100.0)
        for name in ("episodes", "round_episodes"):
            in_range(self, name, 1, 10_000)
        for name in ("epochs", "round_epochs"):
            in_range(self, name, 1, 1000)
        in_range(self, "rounds", 0, 100)
        in_range(self, "beta", 0.0, 1.0)
        in_range(self, "learning_rate", 0.0, 1.0, low_open=True)
        if self.node_range is not None:
            require_node_range(self.node_range, ", or null", name="imitation.node_range")

    @property
    def total_episodes(self) -> int:
        return self.episodes + self.rounds * self.round_episodes

    def teacher(self, seed: int) -> Any:
        """The planner, seeded, with this config's docking margin (a `Policy`)."""
        from iout_mj.agents.registry import make_policy

        policy = make_policy(self.planner, seed)
        if self.teacher_dock_spare_slots is not None:
            policy.dock_spare_slots = self.teacher_dock_spare_slots  # type: ignore[attr-defined]
        return policy


@dataclass(frozen=True)
class TrainConfig:
    """Hyperparameters (rl-zoo style), keyed by scenario; the defaults are those of the
    shipped configs in training/configs."""

    name: str = "ppo"
    n_auvs: int | None = None
    """AUVs; None: the env config's."""
    n_nodes: int | None = None
    """Nodes; None: the env config's (its own nodes if it sets them, else 7)."""
    layout: str | None = None
    """"paper" or "random"; None: the env config's own nodes if it sets them, else "paper"."""
    env: Config = field(default_factory=Config)
    """The env config trained on (nodes, current, noise, reward, physics...); N, K and the
    layout above resolve with it as everywhere (`scenarios.resolve`, `env_spec`)."""
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
    policy: str = "mlp"
    """"mlp" (the flat observation, one K) or "tokens" (`agents.token_policy`, any K)."""
    node_range: tuple[int, int] = (3, 20)
    """tokens: K of the scenario cells trained on (every K in the range, random layouts)."""
    noise_models: tuple[str, ...] = ("flat", "wenz")
    """tokens: the noise models of the cells (each K with each model)."""
    width: int = 64
    """tokens: the width of the token network."""
    imitation: ImitationConfig | None = None
    """tokens: warm start by DAgger from a planner before PPO (None: none)."""
    seed: int = 0
    eval_every_steps: int = 20_000
    eval_episodes: int = 10
    eval_node_range: tuple[int, int] | None = None
    """tokens: the held-out episodes' K, spread evenly over [low, high] (a policy for a range of
    K selects its snapshot over that range); None: n_nodes in every episode."""
    torch_threads: int = 1

    def __post_init__(self) -> None:
        check_run_config(self)
        in_range(self, "n_envs", 1, MAX_ENVS)
        in_range(self, "n_steps", 1, MAX_ROLLOUT_STEPS)
        in_range(self, "batch_size", 1, MAX_ROLLOUT_STEPS)
        in_range(self, "n_epochs", 1, 1000)
        in_range(self, "eval_every_steps", 1, MAX_TIMESTEPS)
        in_range(self, "eval_episodes", 1, 10_000)
        in_range(self, "torch_threads", 1, 256)
        in_range(self, "seed", 0, 2**32 - 1, "numpy's seed range")
        in_range(self, "learning_rate", 0.0, 1.0, low_open=True)
        in_range(self, "learning_rate_final", 0.0, 1.0)
        in_range(self, "ent_coef", 0.0, 1.0)
        in_range(self, "clip_range", 0.0, 1.0, low_open=True)
        require(0 < self.gamma <= 1, "gamma", self.gamma, "a number in (0, 1]")
        require(0 <= self.gae_lambda <= 1, "gae_lambda", self.gae_lambda, "a number in [0, 1]")
        require(
            1 <= len(self.net_arch) <= MAX_LAYERS
            and all(1 <= w <= MAX_WIDTH for w in self.net_arch),
            "net_arch",
            self.net_arch,
            f"1 to {MAX_LAYERS} layer widths from 1 to {MAX_WIDTH}",
        )
        require(self.policy in POLICIES, "policy", self.policy, f"one of {POLICIES}")
        require_node_range(self.node_range)
        if self.eval_node_range is not None:
            require(
                self.policy == "tokens",
                "eval_node_range",
                list(self.eval_node_range),
                "null with policy: mlp (it flies one K)",
            )
            require_node_range(self.eval_node_range, name="eval_node_range")
        require(
            bool(self.noise_models)
            and set(self.noise_models) <= set(NOISE_MODELS)
            and len(set(self.noise_models)) == len(self.noise_models),
            "noise_models",
            list(self.noise_models),
            f"a non-empty list of {NOISE_MODELS}, each once (a repeat would double its cells)",
        )
        in_range(self, "width", 4, 1024)
        require(self.width % 4 == 0, "width", self.width, "a multiple of 4 (the attention's heads)")
        require(
            self.envs <= MAX_ENVS,
            "n_envs",
            self.n_envs,
            f"at most {MAX_ENVS} environments in all (here {self.envs}: n_envs per scenario cell)",
        )
        require(
            self.envs * self.n_steps <= MAX_ROLLOUT_STEPS,
            "n_steps",
            self.n_steps,
            f"envs x n_steps = {self.envs * self.n_steps} transitions per rollout at most "
            f"{MAX_ROLLOUT_STEPS} (the rollout buffer holds them all)",
        )
        if self.imitation is not None:
            slots = self.imitation.total_episodes * self.env.scenario.horizon_slots
            require(
                slots <= MAX_IMITATION_SLOTS,
                "imitation.episodes",
                self.imitation.episodes,
                f"(episodes + rounds x round_episodes) x env.scenario.horizon_slots = {slots} "
                f"recorded slots at most {MAX_IMITATION_SLOTS} (the data set holds them all)",
            )
        if (self.envs * self.n_steps) % self.batch_size:
            raise ConfigError(
                f"batch_size={self.batch_size} must divide n_envs*n_steps="
                f"{self.envs * self.n_steps}"
            )
        if not 1 <= len(self.phases) <= 16:
            raise ConfigError(
                "phases: accepted a list of 1 to 16 {backend, timesteps, node_range (optional)}"
            )
        if self.policy == "mlp" and any(p.node_range is not None for p in self.phases):
            raise ConfigError(
                "phases: node_range (a curriculum over K) is for policy: tokens; accepted null "
                "with policy: mlp (one scenario)"
            )
        # last: resolving builds env sections, whose checks note under their own names
        self.env_spec  # noqa: B018 (resolves the scenario: a contradiction raises here)
        for k in self.eval_node_range or ():
            self.held_out_spec(k)

    def scenario_ks(self, phase: int | None = None) -> list[int]:
        """The K of every scenario cell of one noise model, in `phase` (None: the config's
        node_range): as many cells as node_range spans, their K spread evenly over the
        phase's range (a curriculum keeps the rollout's size and the policy's env count)."""
        return self._spread_ks(None if phase is None else self.phases[phase].node_range)

    def imitation_ks(self) -> list[int]:
        """The K of the imitation's cells of one noise model (`ImitationConfig.node_range`)."""
        return self._spread_ks(None if self.imitation is None else self.imitation.node_range)

    def _spread_ks(self, over: tuple[int, int] | None) -> list[int]:
        lo, hi = self.node_range
        if over is None:
            return list(range(lo, hi + 1))
        return [int(k) for k in np.linspace(over[0], over[1], hi - lo + 1).round()]

    def eval_ks(self) -> list[int]:
        """The K of each held-out episode (`eval_node_range`)."""
        if self.eval_node_range is None:
            return [self.env_spec.n_nodes] * self.eval_episodes
        lo, hi = self.eval_node_range
        return [int(k) for k in np.linspace(lo, hi, self.eval_episodes).round()]

    def held_out_spec(self, n_nodes: int) -> EnvSpec:
        """The scenario of a held-out episode with `n_nodes` nodes."""
        return resolve(self.env, self.n_auvs, n_nodes, self.layout)

    @property
    def envs(self) -> int:
        """Environments trained on: n_envs, or with tokens n_envs per scenario cell."""
        if self.policy == "mlp":
            return self.n_envs
        return self.n_envs * (self.node_range[1] - self.node_range[0] + 1) * len(self.noise_models)

    @property
    def env_spec(self) -> EnvSpec:
        """The scenario trained on: the env config with N, K and the layout resolved (the
        backend is each phase's)."""
        return resolve(self.env, self.n_auvs, self.n_nodes, self.layout)

    @property
    def total_timesteps(self) -> int:
        return sum(p.timesteps for p in self.phases)

    @classmethod
    def load(cls, path: str | Path) -> TrainConfig:
        """A training config file; `base: <file>` in it names the config it varies."""
        data = load_layered(path, "training config", env_files_from_folder)
        config: TrainConfig = build_dataclass(cls, data, Path(path).stem)
        return config

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["phases"] = [
            {k: list(v) if isinstance(v, tuple) else v for k, v in p.items()} for p in d["phases"]
        ]
        d["net_arch"] = list(self.net_arch)
        d["node_range"] = list(self.node_range)
        d["noise_models"] = list(self.noise_models)
        d["env"] = self.env.to_dict()
        return d
