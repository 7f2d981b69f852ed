"""Every non-learning policy by name."""

from __future__ import annotations

from iout_mj.agents.baselines import Greedy, Planner, Policy, RandomWalk, RoundRobin
from iout_mj.agents.planners import CommunicationFirst, TourScheduler
from iout_mj.agents.solver_planner import SolverTour

POLICIES: dict[str, type[Policy]] = {
    "greedy": Greedy,
    "round-robin": RoundRobin,
    "random-walk": RandomWalk,
    "planner": Planner,
    "comm-first": CommunicationFirst,
    "tour-scheduler": TourScheduler,
    "solver-tour": SolverTour,
}


def make_policy(name: str, seed: int | None = 0) -> Policy:
    """A baseline by name."""
    if name not in POLICIES:
        raise ValueError(f"unknown policy {name!r}: accepted {sorted(POLICIES)} or a policy folder")
    policy: Policy = POLICIES[name]()
    policy.reset(seed)
    return policy
