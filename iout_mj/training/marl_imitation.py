"""Warm start of a team policy by DAgger from a centralised planner (`MarlConfig.imitation`).

Every AUV's padded observation is labelled with its share of the planner's joint action. The
shared actor is fitted to those labels by maximum likelihood (absent nodes masked, as in
training) and the critic (MAPPO: on the global state; IPPO: on the AUV's own observation) to
the discounted returns of the scaled team reward, so PPO starts from the planner's behaviour
with a critic that already values it. Round 0 flies the planner; every later round flies the
actor, each AUV on its own observation (the planner's joint action instead with probability
beta, halved every round), and the planner labels the states the actor reaches. The planner
is centralised; the actor it teaches is not: it acts on what one AUV observes.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from torch import nn

from iout_mj.agents.team_policy import ACTION_DIMS, padded_observations, padded_state
from iout_mj.training.imitation import discounted_returns

if TYPE_CHECKING:
    from iout_mj.training.marl import Learner

Actor = Callable[[np.ndarray], np.ndarray]
"""(N, D) padded observations -> (N, 4) actions."""


@dataclass
class TeamDemonstrations:
    """Per joint step: every AUV's padded observation, the global state and the planner's
    action per AUV; per episode, the team's rewards."""

    obs: list[np.ndarray] = field(default_factory=list)
    states: list[np.ndarray] = field(default_factory=list)
    actions: list[np.ndarray] = field(default_factory=list)
    rewards: list[np.ndarray] = field(default_factory=list)

    def returns(self, gamma: float, scale: float) -> np.ndarray:
        """The discounted return of the scaled team reward from every step."""
        return discounted_returns(self.rewards, gamma, scale)


def fly(
    env: Any,
    episodes: int,
    rng: np.random.Generator,
    actor: Actor | None,
    beta: float,
    teacher: Callable[[int], Any],
    into: TeamDemonstrations,
) -> list[dict[str, Any]]:
    """Fly `episodes` episodes of the `TeamEnv` `env`, recording the actions of the teacher
    (`teacher(seed)`, as `ImitationConfig.teacher` makes it) in every state reached; the actor
    acts where given, the teacher with probability beta. Returns each episode's metrics."""
    cfg, metrics = env.cfg, []
    for _ in range(episodes):
        env.reset(seed=int(rng.integers(2**31)))
        mission = env.current.mission
        expert = teacher(int(rng.integers(2**31)))
        rewards: list[float] = []
        while env.agents:
            obs = padded_observations(mission, cfg.n_max, cfg.k_max)
            label = np.asarray(expert(mission), dtype=np.int64).reshape(-1, ACTION_DIMS)
            into.obs.append(obs)
            into.states.append(padded_state(mission, cfg.n_max, cfg.k_max))
            into.actions.append(label)
            act = label if actor is None or rng.random() < beta else actor(obs)
            _, reward, _, _, _ = env.step({a: act[i] for i, a in enumerate(env.possible_agents)})
            rewards.append(float(reward[env.possible_agents[0]]))
        into.rewards.append(np.asarray(rewards))
        metrics.append(mission.metrics())
    return metrics


def greedy_actor(learner: Learner) -> Actor:
    """The actor's most likely action per AUV, on each AUV's own observation."""
    from iout_mj.training.marl import TeamActions

    def act(obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            logits, present = learner.actor(torch.as_tensor(obs))
            mode = TeamActions(logits, present, tuple(learner.nvec)).mode
        return mode.numpy()

    return act


def values(learner: Learner, obs: torch.Tensor, states: torch.Tensor) -> torch.Tensor:
    """The critic's (B, N) values: of the global state (MAPPO) or of each AUV's observation."""
    if learner.cfg.algorithm == "mappo":
        return learner.critic(states)[..., 0]
    return learner.critic(obs)[..., 0]


def fit(
    learner: Learner,
    data: TeamDemonstrations,
    epochs: int,
    learning_rate: float,
    rng: np.random.Generator,
    batch_size: int = 256,
) -> tuple[list[float], float]:
    """Fit the actor to the planner's actions and the critic to the returns; returns the
    actor's accuracy per action field (heading, speed, AET node, uplink node) over every
    recorded AUV decision and the last negative log-likelihood."""
    from iout_mj.training.marl import TeamActions

    cfg, nvec = learner.cfg, tuple(learner.nvec)
    obs = torch.as_tensor(np.stack(data.obs))
    states = torch.as_tensor(np.stack(data.states))
    actions = torch.as_tensor(np.stack(data.actions))
    targets = torch.as_tensor(data.returns(cfg.gamma, cfg.reward_scale), dtype=torch.float32)
    params = list(learner.actor.parameters()) + list(learner.critic.parameters())
    optimizer = torch.optim.Adam(params, lr=learning_rate)
    nll_value = float("nan")
    for _ in range(epochs):
        order = torch.as_tensor(rng.permutation(len(obs)))
        for i in range(0, len(obs), batch_size):
            idx = order[i : i + batch_size]
            logits, present = learner.actor(obs[idx])
            nll = -TeamActions(logits, present, nvec).log_prob(actions[idx]).mean()
            v = values(learner, obs[idx], states[idx])
            loss = nll + 0.5 * nn.functional.mse_loss(v, targets[idx, None].expand_as(v))
            optimizer.zero_grad()
            loss.backward()
            nn.utils.clip_grad_norm_(params, cfg.max_grad_norm)
            optimizer.step()
            nll_value = float(nll.detach())
    with torch.no_grad():
        logits, present = learner.actor(obs)
        mode = TeamActions(logits, present, nvec).mode
    accuracy = (mode == actions).float().reshape(-1, ACTION_DIMS).mean(0)
    return [round(float(a), 4) for a in accuracy], round(nll_value, 4)


def warm_start(learner: Learner, env: Any, progress: bool = True) -> dict[str, Any]:
    """DAgger from `learner.cfg.imitation` on the `TeamEnv` `env`; returns its wall time and a
    record per round: states, accuracy, negative log-likelihood and the flown episodes' mean
    AoI over T_max and docking share."""
    im = learner.cfg.imitation
    assert im is not None
    start = time.perf_counter()
    rng = np.random.default_rng(learner.cfg.seed)
    data = TeamDemonstrations()
    rounds = []
    flown = fly(env, im.episodes, rng, None, 1.0, im.teacher, data)
    for r in range(im.rounds + 1):
        epochs = im.epochs if r == 0 else im.round_epochs
        accuracy, nll = fit(learner, data, epochs, im.learning_rate, rng)
        row = {
            "round": r,
            "states": len(data.obs),
            "accuracy": accuracy,
            "nll": nll,
            "flown_mean_aoi_horizon": round(
                float(np.mean([m["mean_aoi_horizon"] for m in flown])), 3
            ),
            "flown_docked_rate": float(np.mean([all(m["docked"]) for m in flown])),
        }
        rounds.append(row)
        if progress:
            print(json.dumps({"imitation": row}), flush=True)
        if r < im.rounds:
            beta = im.beta / 2**r
            actor = greedy_actor(learner)
            flown = fly(env, im.round_episodes, rng, actor, beta, im.teacher, data)
    seconds = round(time.perf_counter() - start, 1)
    return {"planner": im.planner, "seconds": seconds, "rounds": rounds}
