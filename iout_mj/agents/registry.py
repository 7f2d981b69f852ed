"""Every non-learning policy by name."""

from __future__ import annotations

from iout_mj.agents.baselines import Greedy, Planner, Policy, RandomWalk, RoundRobin
from iout_mj.agents.planners import CommunicationFirst, TourScheduler
from iout_mj.agents.solver_planner import SolverTour
from iout_mj.errors import PolicyError, require_seed

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
    """A baseline by name, seeded by `seed` (an integer >= 0, or None: fresh entropy)."""
    if not isinstance(name, str) or name not in POLICIES:
        raise PolicyError(
            f"unknown policy {name!r}: accepted {sorted(POLICIES)} or a policy folder"
        )
    seed = require_seed(seed, allow_none=True)
    policy: Policy = POLICIES[name]()
    policy.reset(seed)
    return policy
