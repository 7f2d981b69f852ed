"""Warm start of a general policy by imitation of a planner (DAgger), inside SB3's policy.

Round 0 flies the planner and records its actions on token observations; every later round
flies the current policy (the planner's action with probability `beta`) and records what the
planner would have done in the states the policy reaches, and the policy is trained on all
rounds so far: the log-likelihood of the planner's actions through the SB3 policy's own
`evaluate_actions`, and its critic on the discounted returns of the rewards as PPO's
`VecNormalize` will scale them (whose return statistics it also sets).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.running_mean_std import RunningMeanStd

from iout_mj.config import Config
from iout_mj.envs.gym_env import ENV_ID


@dataclass
class Demonstrations:
    """Token observations, the planner's actions, and each step's discounted return."""

    obs: list[np.ndarray] = field(default_factory=list)
    actions: list[np.ndarray] = field(default_factory=list)
    rewards: list[np.ndarray] = field(default_factory=list)
    """Per episode, its rewards."""

    def returns(self, gamma: float, scale: float) -> np.ndarray:
        """Every step's discounted return of the rewards divided by `scale`."""
        return discounted_returns(self.rewards, gamma, 1.0 / scale)


def discounted_returns(rewards: list[np.ndarray], gamma: float, factor: float) -> np.ndarray:
    """Per step of every episode (concatenated), the discounted return of its rewards times
    `factor`."""
    out = []
    for r in rewards:
        g, ret = 0.0, np.empty(len(r))
        for t in range(len(r) - 1, -1, -1):
            g = r[t] * factor + gamma * g
            ret[t] = g
        out.append(ret)
    return np.concatenate(out)


def fly(
    cells: Sequence[tuple[int, Config]],
    episodes: int,
    rng: np.random.RandomState,
    learner: Callable[[np.ndarray], np.ndarray] | None,
    beta: float,
    teacher: Callable[[int], Any],
    into: Demonstrations,
    flown: Callable[[], object] | None = None,
) -> list[dict[str, Any]]:
    """Fly `episodes` kinematic episodes on random cells, recording the teacher's actions
    (`teacher(seed)`: a planner, as `ImitationConfig.teacher` makes it) in the visited states;
    the learner acts where given (the teacher with probability beta);
    `flown()` after every episode."""
    envs: dict[int, Any] = {}
    metrics = []
    for _ in range(episodes):
        c = int(rng.randint(len(cells)))
        if c not in envs:
            k, cfg = cells[c]
            envs[c] = gym.make(ENV_ID, n_nodes=k, backend="kinematic", layout="random", config=cfg)
        env = envs[c]
        seed = int(rng.randint(2**31 - 1))
        env.reset(seed=seed)
        expert = teacher(seed)
        mission, rewards, done = env.unwrapped.mission, [], False
        while not done:
            tokens = mission.observe_tokens()
            label = expert(mission)
            into.obs.append(tokens)
            into.actions.append(label)
            act = label if learner is None or rng.rand() < beta else learner(tokens)
            _, reward, terminated, truncated, info = env.step(act)
            rewards.append(reward)
            done = terminated or truncated
        into.rewards.append(np.asarray(rewards))
        metrics.append(info["metrics"])
        if flown is not None:
            flown()
    for env in envs.values():
        env.close()
    return metrics


def return_statistics(rewards: list[np.ndarray], gamma: float) -> RunningMeanStd:
    """The return statistics VecNormalize would gather over these episodes."""
    rms = RunningMeanStd(shape=())
    for r in rewards:
        ret = 0.0
        for x in r:
            ret = ret * gamma + x
            rms.update(np.array([ret]))
    return rms


def fit(
    policy: Any,
    data: Demonstrations,
    gamma: float,
    epochs: int,
    learning_rate: float = 1e-3,
    rng: np.random.RandomState | None = None,
    batch_size: int = 256,
    epoch_done: Callable[[int], object] | None = None,
) -> tuple[list[float], float, RunningMeanStd]:
    """Train the SB3 policy on the demonstrations (`epoch_done(epochs so far)` after every
    epoch); returns the accuracy of its most likely action per field (heading, speed, AET
    node, uplink node), the last negative log-likelihood and the return statistics."""
    rng = rng or np.random.RandomState(0)
    rms = return_statistics(data.rewards, gamma)
    scale = float(np.sqrt(rms.var + 1e-8))
    obs = torch.as_tensor(np.stack(data.obs))
    actions = torch.as_tensor(np.stack(data.actions))
    targets = torch.as_tensor(data.returns(gamma, scale), dtype=torch.float32)
    policy.set_training_mode(True)
    optimizer = torch.optim.Adam(policy.parameters(), lr=learning_rate)
    loss_pi = float("nan")
    for epoch in range(epochs):
        order = torch.as_tensor(rng.permutation(len(obs)))
        for i in range(0, len(obs), batch_size):
            idx = order[i : i + batch_size]
            values, log_prob, _ = policy.evaluate_actions(obs[idx], actions[idx])
            nll = -log_prob.mean()
            loss = nll + 0.5 * torch.nn.functional.mse_loss(values.flatten(), targets[idx])
            optimizer.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(policy.parameters(), 1.0)
            optimizer.step()
            loss_pi = float(nll.detach())
        if epoch_done is not None:
            epoch_done(epoch + 1)
    policy.set_training_mode(False)
    with torch.no_grad():
        chosen = torch.cat(
            [policy.get_distribution(obs[i : i + 4096]).mode() for i in range(0, len(obs), 4096)]
        )
    accuracy = (chosen == actions).float().mean(0).reshape(-1, 4).mean(0)
    return accuracy.tolist(), loss_pi, rms
