"""Multi-agent PPO on the PettingZoo env with TorchRL: MAPPO and IPPO.

    iout-mj train-marl training/configs/mappo-n2.yaml [--out runs/mappo-n2] [--resume]

Both train one actor shared by every AUV, acting on the AUV's own padded observation
(`agents.team_policy`: decentralised execution, parameter sharing). MAPPO's critic sees the
global state (`ParallelEnv.state()`'s groups, padded: `padded_state`); IPPO's critic is shared
too but sees only the AUV's own observation. TorchRL does the rest: `PettingZooWrapper` on
`TeamEnv` (the PettingZoo env with K drawn per episode from `node_range` and sizes padded to
n_max and k_max), `Collector`, GAE and `ClipPPOLoss`. The logits of absent nodes are
masked in the actor (the action mask, from the observation's node-present flags), so the AET and
uplink nodes are always nodes of the episode. All AUVs of this env end their episode together
(docking does not remove an agent), so no agent mask is needed. With `imitation:` in the
config, actor and critic are first warm-started by DAgger from a centralised planner
(`training.marl_imitation`); PPO from scratch does not learn this task.

A run folder holds `checkpoint/` (actor, critic, Adam's state and the counters, in the safe
policy format), `policy/` (the actor alone: `iout-mj evaluate --policy <out>/policy`), `best/`
(the actor of the best held-out evaluation: docking first, then AoI) and `curve.json`
(held-out evaluations against greedy on the same episodes). `--resume` continues from the
checkpoint: the same weights, optimiser state and counters; the env's episodes then draw from a
seed that depends on the batches done.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from pettingzoo import ParallelEnv
from stable_baselines3.common.policies import ActorCriticPolicy
from tensordict.nn import TensorDictModule
from torch import nn
from torch.distributions import Categorical, Distribution
from torchrl.collectors import Collector
from torchrl.data import LazyTensorStorage, ReplayBuffer
from torchrl.data.replay_buffers.samplers import SamplerWithoutReplacement
from torchrl.envs import RewardScaling, TransformedEnv
from torchrl.envs.libs.pettingzoo import PettingZooWrapper
from torchrl.modules import ProbabilisticActor
from torchrl.objectives import ClipPPOLoss, ValueEstimators

import iout_mj
from iout_mj.agents.policy_format import (
    MANIFEST,
    LoadedPolicy,
    Normalizer,
    load_policy_folder,
    read_manifest,
    read_tensors,
    save_policy,
)
from iout_mj.agents.registry import make_policy
from iout_mj.agents.rollout import run_episode
from iout_mj.agents.shield import DockShield
from iout_mj.agents.team_policy import (
    TeamPolicy,
    masked_logits,
    node_present_slice,
    padded_observations,
    padded_state,
    state_size,
    team_observation_size,
)
from iout_mj.backends.registry import SINGLE_ENV_BACKENDS
from iout_mj.config import Config
from iout_mj.envs.gym_env import ENV_ID
from iout_mj.errors import CheckpointError
from iout_mj.mission import OBS_HIGH, OBS_LOW
from iout_mj.mission.actions import ActionError
from iout_mj.scenarios import resolve
from iout_mj.schema import (
    ConfigError,
    build_dataclass,
    in_range,
    load_layered,
    require,
)
from iout_mj.training import marl_imitation
from iout_mj.training.config import (
    ImitationConfig,
    check_run_config,
    check_types,
    env_files_from_folder,
    require_node_range,
)
from iout_mj.training.trainer import HELD_OUT_SEED

ALGORITHMS = ("mappo", "ippo")
GROUP = "auvs"
OBS, ACTION = (GROUP, "observation"), (GROUP, "action")
CHECKPOINT, POLICY, BEST, CURVE = "checkpoint", "policy", "best", "curve.json"
MAX_AGENT_STEPS = 10**10
MAX_AUVS = 16


@dataclass(frozen=True)
class MarlPhase:
    """One training phase on one backend."""

    backend: str = "kinematic"
    agent_steps: int = 100_000
    """AUV decisions (N per joint step) in this phase."""

    def __post_init__(self) -> None:
        check_types(self)
        require(
            self.backend in SINGLE_ENV_BACKENDS,
            "backend",
            self.backend,
            f"one of {SINGLE_ENV_BACKENDS}",
        )
        in_range(self, "agent_steps", 1, MAX_AGENT_STEPS)


@dataclass(frozen=True)
class MarlConfig:
    """A MAPPO or IPPO run (`training/configs/mappo-*.yaml`, `ippo-*.yaml`)."""

    name: str = "mappo"
    algorithm: str = "mappo"
    """mappo: the critic sees the global state; ippo: the AUV's own observation."""
    n_auvs: int = 2
    n_max: int = 4
    """The actor's padded size: the exported policy flies any N <= n_max."""
    node_range: tuple[int, int] = (3, 10)
    """K of each training episode, drawn uniformly; its high end is the padded k_max."""
    layout: str = "random"
    env: Config = field(default_factory=Config)
    imitation: ImitationConfig | None = None
    """Warm start of actor and critic by DAgger from a centralised planner before PPO
    (`training.marl_imitation`); null: PPO from scratch."""
    shield: bool = False
    """Train and evaluate under the docking shield (`agents.shield`): the env flies every
    joint action shielded, so an AUV's docking is the shield's and its reward is the AoI's;
    the policy then flies as `<policy>+dock`."""
    phases: tuple[MarlPhase, ...] = (MarlPhase(),)
    steps_per_batch: int = 2048
    """Joint steps (TorchRL frames) collected per PPO iteration."""
    minibatch_size: int = 256
    epochs: int = 4
    learning_rate: float = 3e-4
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_epsilon: float = 0.2
    entropy_coef: float = 0.01
    max_grad_norm: float = 1.0
    reward_scale: float = 0.01
    """The team reward is multiplied by this for training (its slots reach -250)."""
    hidden: tuple[int, ...] = (128, 128)
    seed: int = 0
    eval_every_batches: int = 5
    eval_episodes: int = 10
    torch_threads: int = 1

    def __post_init__(self) -> None:
        check_run_config(self)
        require(self.algorithm in ALGORITHMS, "algorithm", self.algorithm, f"one of {ALGORITHMS}")
        in_range(self, "n_auvs", 1, MAX_AUVS)
        in_range(self, "n_max", self.n_auvs, MAX_AUVS)
        require_node_range(self.node_range)
        if self.imitation is not None and self.imitation.node_range is not None:
            raise ConfigError(
                "imitation.node_range: accepted null for a team policy (its imitation flies "
                "the team env's K, drawn from node_range)"
            )
        require(self.layout == "random", "layout", self.layout, "random (K varies per episode)")
        require(1 <= len(self.phases) <= 16, "phases", len(self.phases), "1 to 16 phases")
        in_range(self, "steps_per_batch", 1, 1 << 18)
        in_range(self, "minibatch_size", 1, 1 << 18)
        in_range(self, "epochs", 1, 1000)
        in_range(self, "learning_rate", 0.0, 1.0, low_open=True)
        in_range(self, "entropy_coef", 0.0, 1.0)
        in_range(self, "clip_epsilon", 0.0, 1.0, low_open=True)
        in_range(self, "max_grad_norm", 0.0, 1e6, low_open=True)
        in_range(self, "reward_scale", 0.0, 1e6, low_open=True)
        require(0 < self.gamma <= 1, "gamma", self.gamma, "a number in (0, 1]")
        require(0 <= self.gae_lambda <= 1, "gae_lambda", self.gae_lambda, "a number in [0, 1]")
        require(
            1 <= len(self.hidden) <= 8 and all(1 <= w <= 4096 for w in self.hidden),
            "hidden",
            list(self.hidden),
            "1 to 8 layer widths from 1 to 4096",
        )
        in_range(self, "seed", 0, 2**32 - 1, "numpy's seed range")
        in_range(self, "eval_every_batches", 1, 1 << 20)
        in_range(self, "eval_episodes", 1, 10_000)
        in_range(self, "torch_threads", 1, 256)
        if self.steps_per_batch % self.minibatch_size:
            raise ConfigError(
                f"minibatch_size={self.minibatch_size} must divide steps_per_batch="
                f"{self.steps_per_batch}"
            )
        # last (its env sections' checks note under their own names): the scenario every
        # episode resolves (K varies), N within the env's, no contradiction
        resolve(self.env, self.n_auvs, self.k_max, self.layout)

    @property
    def k_max(self) -> int:
        return self.node_range[1]

    def frames(self, phase: MarlPhase) -> int:
        """A phase's joint steps, whole batches (at least one)."""
        joint = -(-phase.agent_steps // self.n_auvs)
        return max(1, -(-joint // self.steps_per_batch)) * self.steps_per_batch

    @classmethod
    def load(cls, path: str | Path) -> MarlConfig:
        """A MARL config file; `base: <file>` in it names the config it varies."""
        config: MarlConfig = build_dataclass(
            cls, load_layered(path, "MARL config", env_files_from_folder), Path(path).stem
        )
        return config

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["node_range"], d["hidden"] = list(self.node_range), list(self.hidden)
        d["phases"] = [asdict(p) for p in self.phases]
        d["env"] = self.env.to_dict()
        return d


class TeamEnv(ParallelEnv):
    """The PettingZoo env with K drawn per episode from `node_range` (random layouts) and every
    observation padded to n_max AUVs and k_max nodes (`agents.team_policy`); `state()` is the
    padded global state. Rewards, terminations and truncations are the env's; infos are empty
    (TorchRL's wrapper keeps only fixed-shape infos)."""

    metadata = {"name": "iout_mj_team_v0", "render_modes": []}  # noqa: RUF012

    def __init__(self, cfg: MarlConfig, backend: str, seed: int):
        self.cfg, self.backend = cfg, backend
        self.rng = np.random.default_rng(seed)
        self._envs: dict[int, Any] = {}
        self.possible_agents = [f"auv_{i}" for i in range(cfg.n_auvs)]
        self.agents: list[str] = []
        size = team_observation_size(cfg.n_max, cfg.k_max)
        self._obs_space = gym.spaces.Box(OBS_LOW, OBS_HIGH, shape=(size,), dtype=np.float32)
        motion = cfg.env.motion
        self._act_space = gym.spaces.MultiDiscrete(
            [motion.heading_levels, motion.speed_levels, cfg.k_max, cfg.k_max]
        )
        shape = (state_size(cfg.n_max, cfg.k_max),)
        self.state_space = gym.spaces.Box(OBS_LOW, OBS_HIGH, shape=shape, dtype=np.float32)
        self.current = self._env(cfg.node_range[0])
        self.shield = DockShield() if cfg.shield else None

    def observation_space(self, agent: str) -> gym.spaces.Box:
        return self._obs_space

    def action_space(self, agent: str) -> gym.spaces.MultiDiscrete:
        return self._act_space

    def _env(self, k: int) -> Any:
        if k not in self._envs:
            self._envs[k] = iout_mj.parallel_env(
                n_auvs=self.cfg.n_auvs,
                n_nodes=k,
                backend=self.backend,
                layout=self.cfg.layout,
                config=self.cfg.env,
            )
        return self._envs[k]

    def _observe(self) -> dict[str, np.ndarray]:
        obs = padded_observations(self.current.mission, self.cfg.n_max, self.cfg.k_max)
        return {a: obs[i] for i, a in enumerate(self.possible_agents)}

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict[str, Any]]]:
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        lo, hi = self.cfg.node_range
        self.current = self._env(int(self.rng.integers(lo, hi + 1)))
        self.current.reset(seed=int(self.rng.integers(2**31)))
        self.agents = list(self.possible_agents)
        return self._observe(), {a: {} for a in self.agents}

    def step(self, actions: dict[str, Any]) -> tuple[Any, Any, Any, Any, Any]:
        k = self.current.mission.n_nodes
        for agent, action in actions.items():
            nodes = np.asarray(action)[2:]
            if np.any(nodes >= k):
                raise ActionError(
                    f"actions[{agent!r}] names node {nodes.tolist()} in an episode of K={k} "
                    f"nodes: accepted node indices from 0 to {k - 1}"
                )
        if self.shield is not None:
            agents = self.possible_agents
            joint = np.stack([np.asarray(actions[a], dtype=np.int64) for a in agents])
            joint = self.shield.apply(self.current.mission, joint)
            actions = {a: joint[i] for i, a in enumerate(agents)}
        _, rewards, term, trunc, _ = self.current.step(actions)
        obs = self._observe()
        if any(term.values()) or any(trunc.values()):
            self.agents = []
        return obs, rewards, term, trunc, {a: {} for a in self.possible_agents}

    def state(self) -> np.ndarray:
        return padded_state(self.current.mission, self.cfg.n_max, self.cfg.k_max)

    def close(self) -> None:
        for env in self._envs.values():
            env.close()


class TeamActions(Distribution):
    """Independent categoricals over (heading, speed, AET node, uplink node), the node logits
    of absent nodes masked (`team_policy.masked_logits`)."""

    arg_constraints: dict[str, Any] = {}  # noqa: RUF012

    def __init__(self, logits: torch.Tensor, present: torch.Tensor, nvec: tuple[int, ...]):
        self.parts = [Categorical(logits=p) for p in masked_logits(logits, list(nvec), present)]
        super().__init__(batch_shape=logits.shape[:-1], validate_args=False)

    def sample(self, sample_shape: torch.Size | list[int] | tuple[int, ...] = ()) -> torch.Tensor:
        return torch.stack([p.sample(sample_shape) for p in self.parts], dim=-1)

    def log_prob(self, value: torch.Tensor) -> torch.Tensor:
        return sum(p.log_prob(value[..., i]) for i, p in enumerate(self.parts))

    def entropy(self) -> torch.Tensor:
        return sum(p.entropy() for p in self.parts)

    @property
    def mode(self) -> torch.Tensor:
        return torch.stack([p.probs.argmax(-1) for p in self.parts], dim=-1)

    @property
    def deterministic_sample(self) -> torch.Tensor:
        return self.mode


def mlp(n_in: int, hidden: tuple[int, ...], n_out: int) -> nn.Sequential:
    """Linear layers with tanh between them (SB3's MLP policy's layout)."""
    layers: list[nn.Module] = []
    for width in hidden:
        layers += [nn.Linear(n_in, width), nn.Tanh()]
        n_in = width
    return nn.Sequential(*layers, nn.Linear(n_in, n_out))


class ActorNet(nn.Module):
    """The shared actor: logits from an AUV's padded observation, and its node-present flags
    (applied by `TeamActions`). Applied to (..., N, D) it shares its weights across AUVs."""

    def __init__(self, cfg: MarlConfig, nvec: list[int]):
        super().__init__()
        self.net = mlp(team_observation_size(cfg.n_max, cfg.k_max), cfg.hidden, sum(nvec))
        self.present = node_present_slice(cfg.n_max, cfg.k_max)

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.net(obs), obs[..., self.present]


class CentralCritic(nn.Module):
    """MAPPO's critic: one value of the global state, the same for every AUV."""

    def __init__(self, cfg: MarlConfig):
        super().__init__()
        self.net = mlp(state_size(cfg.n_max, cfg.k_max), cfg.hidden, 1)
        self.n_auvs = cfg.n_auvs

    def forward(self, state: torch.Tensor) -> torch.Tensor:
        value = self.net(state).unsqueeze(-2)
        return value.expand(*value.shape[:-2], self.n_auvs, 1)


@dataclass
class Learner:
    """The actor, the critic, the PPO loss and its optimiser."""

    cfg: MarlConfig
    nvec: list[int]
    actor: ActorNet
    critic: nn.Module
    policy: ProbabilisticActor
    loss: ClipPPOLoss
    optim: torch.optim.Adam


def make_learner(cfg: MarlConfig) -> Learner:
    motion = cfg.env.motion
    nvec = [motion.heading_levels, motion.speed_levels, cfg.k_max, cfg.k_max]
    actor = ActorNet(cfg, nvec)
    policy = ProbabilisticActor(
        TensorDictModule(actor, in_keys=[OBS], out_keys=[(GROUP, "logits"), (GROUP, "present")]),
        in_keys={"logits": (GROUP, "logits"), "present": (GROUP, "present")},
        out_keys=[ACTION],
        distribution_class=TeamActions,
        distribution_kwargs={"nvec": tuple(nvec)},
        return_log_prob=True,
    )
    critic: nn.Module
    value_in: str | tuple[str, str]
    if cfg.algorithm == "mappo":
        critic = CentralCritic(cfg)
        value_in = "state"
    else:
        critic = mlp(team_observation_size(cfg.n_max, cfg.k_max), cfg.hidden, 1)
        value_in = OBS
    value = TensorDictModule(critic, in_keys=[value_in], out_keys=[(GROUP, "state_value")])
    loss = ClipPPOLoss(
        policy,
        value,
        clip_epsilon=cfg.clip_epsilon,
        entropy_coeff=cfg.entropy_coef,
        normalize_advantage=True,
    )
    loss.set_keys(
        reward=(GROUP, "reward"),
        action=ACTION,
        value=(GROUP, "state_value"),
        done=(GROUP, "done"),
        terminated=(GROUP, "terminated"),
    )
    loss.make_value_estimator(ValueEstimators.GAE, gamma=cfg.gamma, lmbda=cfg.gae_lambda)
    optim = torch.optim.Adam(loss.parameters(), lr=cfg.learning_rate)
    return Learner(cfg, nvec, actor, critic, policy, loss, optim)


def torchrl_env(cfg: MarlConfig, backend: str, seed: int) -> TransformedEnv:
    """`TeamEnv` as a TorchRL env: one group of N agents, the state for MAPPO's critic, the
    reward scaled by `reward_scale`."""
    env = PettingZooWrapper(
        TeamEnv(cfg, backend, seed),
        return_state=True,
        group_map={GROUP: [f"auv_{i}" for i in range(cfg.n_auvs)]},
        categorical_actions=True,
        seed=seed,
    )
    scale = RewardScaling(loc=0.0, scale=cfg.reward_scale, in_keys=[(GROUP, "reward")])
    return TransformedEnv(env, scale)


def update(learner: Learner, data: Any) -> dict[str, float]:
    """PPO's epochs on one batch (TorchRL's GAE and clipped loss); the mean loss terms."""
    cfg, loss = learner.cfg, learner.loss
    with torch.no_grad():
        loss.value_estimator(
            data,
            params=loss.critic_network_params,
            target_params=loss.target_critic_network_params,
        )
    flat = data.reshape(-1)
    buffer = ReplayBuffer(
        storage=LazyTensorStorage(flat.numel()),
        sampler=SamplerWithoutReplacement(),
        batch_size=cfg.minibatch_size,
    )
    buffer.extend(flat)
    sums: dict[str, float] = {}
    count = 0
    for _ in range(cfg.epochs):
        for _ in range(flat.numel() // cfg.minibatch_size):
            terms = loss(buffer.sample())
            total = terms["loss_objective"] + terms["loss_critic"] + terms["loss_entropy"]
            total.backward()
            nn.utils.clip_grad_norm_(loss.parameters(), cfg.max_grad_norm)
            learner.optim.step()
            learner.optim.zero_grad()
            for key in ("loss_objective", "loss_critic", "loss_entropy"):
                sums[key] = sums.get(key, 0.0) + terms[key].item()
            count += 1
    return {k: v / count for k, v in sums.items()}


def sb3_actor(policy: ActorCriticPolicy) -> nn.Sequential:
    """The actor's layers of an SB3 MLP policy, in `mlp`'s order."""
    return nn.Sequential(policy.mlp_extractor.policy_net, policy.action_net)


def copy_linears(src: nn.Module, dst: nn.Module) -> None:
    """Copy the linear layers of `src` into those of `dst`, in order (same shapes)."""
    pairs = zip(
        [m for m in src.modules() if isinstance(m, nn.Linear)],
        [m for m in dst.modules() if isinstance(m, nn.Linear)],
        strict=True,
    )
    with torch.no_grad():
        for a, b in pairs:
            b.weight.copy_(a.weight)
            b.bias.copy_(a.bias)


def actor_policy(learner: Learner) -> ActorCriticPolicy:
    """The actor as an SB3 MLP policy (same layers, no value layers), for the policy format."""
    cfg = learner.cfg
    size = team_observation_size(cfg.n_max, cfg.k_max)
    sb3 = ActorCriticPolicy(
        gym.spaces.Box(-1.0, 2.0, shape=(size,), dtype=np.float32),
        gym.spaces.MultiDiscrete(learner.nvec),
        lambda _: 0.0,
        net_arch={"pi": list(cfg.hidden), "vf": []},
        activation_fn=nn.Tanh,
        ortho_init=False,
    )
    copy_linears(learner.actor.net, sb3_actor(sb3))
    sb3.set_training_mode(False)
    return sb3


IDENTITY = {"obs_count": 0.0, "clip_obs": 10.0, "epsilon": 1e-8}
"""The observations are used as the compiled rules scale them (no running normalisation)."""


def identity_normalization(size: int) -> dict[str, Any]:
    return {"obs_mean": [0.0] * size, "obs_var": [1.0] * size, **IDENTITY}


def team_manifest(cfg: MarlConfig) -> dict[str, Any]:
    return {
        "algorithm": cfg.algorithm.upper(),
        "n_auvs": cfg.n_auvs,
        "n_nodes": cfg.k_max,
        "team": {"algorithm": cfg.algorithm, "n_max": cfg.n_max, "k_max": cfg.k_max},
        "env_config": cfg.env.to_dict(),
        "training": cfg.to_dict(),
    }


def flown_policy(learner: Learner) -> Any:
    """The current actor as it is evaluated: shielded when it trains under the shield."""
    policy = team_policy(learner)
    return DockShield(policy) if learner.cfg.shield else policy


def team_policy(learner: Learner) -> TeamPolicy:
    """The current actor as a `TeamPolicy` (what `export` stores), without a file."""
    cfg = learner.cfg
    size = team_observation_size(cfg.n_max, cfg.k_max)
    identity = Normalizer(np.zeros(size), np.ones(size), 0.0, 10.0, 1e-8)
    manifest = {"action_nvec": learner.nvec, **team_manifest(cfg)}
    return TeamPolicy(LoadedPolicy(actor_policy(learner), identity, manifest))


def export(
    learner: Learner,
    folder: Path,
    extra: dict[str, torch.Tensor] | None = None,
    run: dict[str, Any] | None = None,
) -> None:
    """The actor in the safe policy format (`iout-mj evaluate --policy <folder>`); a
    checkpoint adds the critic, Adam's state and the run's counters."""
    cfg = learner.cfg
    size = team_observation_size(cfg.n_max, cfg.k_max)
    manifest = team_manifest(cfg) | ({"run": run} if run is not None else {})
    save_policy(folder, actor_policy(learner), identity_normalization(size), manifest, extra)


def checkpoint_tensors(learner: Learner) -> dict[str, torch.Tensor]:
    """The critic's weights, Adam's moments and step counts, and torch's RNG state."""
    out = {f"critic.{k}": v.detach().clone() for k, v in learner.critic.state_dict().items()}
    for i, state in learner.optim.state_dict()["state"].items():
        for key, value in state.items():
            out[f"optim.{i}.{key}"] = torch.as_tensor(value).detach().clone()
    out["rng.torch"] = torch.get_rng_state()
    return out


def restore(learner: Learner, folder: Path) -> dict[str, Any]:
    """Load a checkpoint into `learner`; returns the run's counters."""
    try:
        loaded = load_policy_folder(folder)
        manifest = read_manifest(folder)
        tensors = read_tensors(folder, manifest)
    except Exception as exc:
        raise CheckpointError(f"cannot resume from {folder}: {exc}") from exc
    trained, now = dict(manifest.get("training", {})), learner.cfg.to_dict()
    for d in (trained, now):
        d.pop("phases", None)
    if trained != now:
        changed = sorted(k for k in set(trained) | set(now) if trained.get(k) != now.get(k))
        raise CheckpointError(
            f"{folder} was written with other settings ({', '.join(changed)}): accepted a "
            "resume with the same config (only the phases' agent steps may differ)"
        )
    copy_linears(sb3_actor(loaded.policy), learner.actor.net)
    critic = {k[len("critic.") :]: v for k, v in tensors.items() if k.startswith("critic.")}
    learner.critic.load_state_dict(critic, strict=True)
    state = learner.optim.state_dict()
    for key, value in tensors.items():
        if key.startswith("optim."):
            _, i, name = key.split(".")
            state["state"].setdefault(int(i), {})[name] = value
    learner.optim.load_state_dict(state)
    torch.set_rng_state(tensors["rng.torch"])
    run: dict[str, Any] = manifest["run"]
    return run


@dataclass
class Episodes:
    """Held-out episodes: seeds from HELD_OUT_SEED, K drawn from node_range per seed."""

    seeds: list[int]
    ks: list[int]


def held_out(cfg: MarlConfig) -> Episodes:
    rng = np.random.default_rng(HELD_OUT_SEED)
    lo, hi = cfg.node_range
    ks = [int(k) for k in rng.integers(lo, hi + 1, size=cfg.eval_episodes)]
    return Episodes([HELD_OUT_SEED + i for i in range(cfg.eval_episodes)], ks)


def fly(cfg: MarlConfig, policy: Any, episodes: Episodes, backend: str) -> dict[str, float]:
    """Mean AoI over T_max and the share of episodes with every AUV docked."""
    aoi, docked = [], []
    for seed, k in zip(episodes.seeds, episodes.ks, strict=True):
        env = gym.make(
            ENV_ID,
            backend=backend,
            n_auvs=cfg.n_auvs,
            n_nodes=k,
            layout=cfg.layout,
            config=cfg.env,
        )
        metrics = run_episode(env, policy, seed)
        env.close()
        aoi.append(metrics["mean_aoi_horizon"])
        docked.append(float(all(metrics["docked"])))
    return {"mean_aoi_horizon": float(np.mean(aoi)), "docked_rate": float(np.mean(docked))}


def greedy_policy() -> Any:
    greedy = make_policy("greedy")

    def act(env: Any, _obs: np.ndarray) -> np.ndarray:
        return greedy(env.unwrapped.mission)

    act.reset = greedy.reset  # type: ignore[attr-defined]
    return act


def _write_json(path: Path, data: Any) -> None:
    path.write_text(json.dumps(data, indent=2) + "\n")


def record(
    learner: Learner, out: Path, run: dict[str, Any], row: dict[str, Any], progress: bool
) -> None:
    """Add a held-out evaluation to the run's curve and write the checkpoint; the actor goes to
    `best/` too when it is the best so far: the highest docking share, then the lowest AoI."""
    run["curve"].append(row)
    if progress:
        print(json.dumps(row), flush=True)
    rank = [-row["docked_rate"], row["mean_aoi_horizon"]]
    if "best" not in run or rank < run["best"]["rank"]:
        run["best"] = {"agent_steps": row["agent_steps"], "rank": rank}
        export(learner, out / BEST)
    export(learner, out / CHECKPOINT, checkpoint_tensors(learner), run)


def train_marl(
    cfg: MarlConfig, out: Path, resume: bool = False, progress: bool = True
) -> dict[str, Any]:
    """Train `cfg` into the run folder `out` (see the module docstring); returns the summary:
    agent steps, wall time, agent steps per second, the last held-out evaluation and greedy's
    on the same episodes."""
    torch.manual_seed(cfg.seed)
    torch.set_num_threads(cfg.torch_threads)
    learner = make_learner(cfg)
    out.mkdir(parents=True, exist_ok=True)
    run: dict[str, Any] = {"batches": 0, "agent_steps": 0, "seconds": 0.0, "curve": []}
    if resume:
        if not (out / CHECKPOINT / MANIFEST).is_file():
            raise CheckpointError(f"{out} has no {CHECKPOINT}/ to resume: accepted a run folder")
        run = restore(learner, out / CHECKPOINT)
    elif (out / CHECKPOINT).exists():
        raise CheckpointError(
            f"{out} already holds a run: accepted --resume to continue it or another --out"
        )
    episodes = held_out(cfg)
    greedy = {b: fly(cfg, greedy_policy(), episodes, b) for b in {p.backend for p in cfg.phases}}
    if cfg.imitation is not None and "imitation" not in run:
        env = TeamEnv(cfg, "kinematic", cfg.seed)
        run["imitation"] = marl_imitation.warm_start(learner, env, progress)
        env.close()
        row = {"agent_steps": 0, "seconds": 0.0, "backend": "kinematic"}
        row |= fly(cfg, flown_policy(learner), episodes, "kinematic")
        record(learner, out, run, row, progress)
    batch_index = 0
    for phase in cfg.phases:
        frames = cfg.frames(phase)
        batches = frames // cfg.steps_per_batch
        todo = max(0, batch_index + batches - run["batches"])
        batch_index += batches
        if todo == 0:
            continue
        env = torchrl_env(cfg, phase.backend, cfg.seed + 7919 * run["batches"])
        collector = Collector(
            env,
            learner.policy,
            frames_per_batch=cfg.steps_per_batch,
            total_frames=todo * cfg.steps_per_batch,
            auto_register_policy_transforms=False,
        )
        start = time.perf_counter()
        for data in collector:
            terms = update(learner, data)
            collector.update_policy_weights_()
            run["batches"] += 1
            run["agent_steps"] += cfg.steps_per_batch * cfg.n_auvs
            run["seconds"] += time.perf_counter() - start
            start = time.perf_counter()
            if run["batches"] % cfg.eval_every_batches == 0 or run["batches"] == batch_index:
                row = {
                    "agent_steps": run["agent_steps"],
                    "seconds": round(run["seconds"], 1),
                    "backend": phase.backend,
                    **fly(cfg, flown_policy(learner), episodes, phase.backend),
                    **terms,
                }
                record(learner, out, run, row, progress)
                start = time.perf_counter()
        collector.shutdown()
        env.close()
    export(learner, out / POLICY)
    last = run["curve"][-1] if run["curve"] else {}
    summary = {
        "name": cfg.name,
        "algorithm": cfg.algorithm,
        "agent_steps": run["agent_steps"],
        "train_seconds": round(run["seconds"], 1),
        "agent_steps_per_s": round(run["agent_steps"] / max(run["seconds"], 1e-9), 1),
        "final": {k: last.get(k) for k in ("mean_aoi_horizon", "docked_rate")},
        "greedy": greedy,
        "imitation": run.get("imitation"),
        "best": run.get("best"),
        "episodes": asdict(episodes),
        "policy": str(out / POLICY),
    }
    _write_json(out / CURVE, {"greedy": greedy, "curve": run["curve"], **summary})
    return summary
