"""The reward: one small function per term, each scaled by its signed weight.

Every term reads a `SlotContext` (what happened in the slot, with leading batch axes) and
returns one value per environment; the reward is their sum, in the order of `REWARD_TERMS`,
and every term is logged (`info["reward_terms"]`, TensorBoard). Weights live in
`RewardWeights` with their signs; thresholds in `RewardConfig`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from iout_mj.config import RewardConfig
from iout_mj.types import BoolArray, FloatArray
from iout_mj.world.geometry import norm_xy, pair_indices


@dataclass(frozen=True)
class SlotContext:
    """What a slot did, as the reward terms read it (leading batch axes omitted)."""

    active: BoolArray
    """(N,) AUVs not docked at the start of the slot."""
    moved_m: FloatArray
    """(N,) displacement over the slot."""
    boundary_attempt: BoolArray
    """(N,) the slot's straight move would have left the area."""
    positions_m: FloatArray
    """(N, 2) positions at the end of the slot."""
    docked: BoolArray
    """(N,) docked at the end of the slot."""
    newly_docked: BoolArray
    """(N,) entered the dock in this slot."""
    all_docked_first: Any
    """() every AUV is docked, for the first time in the episode."""
    dock_dist_before_m: FloatArray
    dock_dist_m: FloatArray
    slack_before_m: FloatArray
    """(N,) deadline slack at the start of the slot (see `Mission`)."""
    slack_m: FloatArray
    mean_aoi: Any
    jain: Any
    deliveries: Any
    """() deliveries so far, all nodes."""
    uplink_stored_j: FloatArray
    """(N,) energy stored at the start of the slot at the node each AUV collects from."""
    uplink_req_j: FloatArray
    """(N,) the energy that node needs to reach the AUV."""
    ending: Any
    """() the episode ends with this slot."""
    aoi_after_mission: Any
    """() mean-AoI sum of the unserved slots left until T_max (0 unless ending early)."""


Term = Callable[[SlotContext, RewardConfig], Any]


def _docking_progress(c: SlotContext, r: RewardConfig) -> Any:
    return r.weights.docking_progress * (c.dock_dist_before_m - c.dock_dist_m).sum(-1)


def _aoi(c: SlotContext, r: RewardConfig) -> Any:
    return r.weights.aoi * c.mean_aoi


def _fairness(c: SlotContext, r: RewardConfig) -> Any:
    served = c.deliveries > r.fairness_min_deliveries
    return np.where(served, r.weights.fairness * (1.0 - c.jain), 0.0)


def _boundary(c: SlotContext, r: RewardConfig) -> Any:
    return r.weights.boundary * c.boundary_attempt.sum(axis=-1)


def _stall(c: SlotContext, r: RewardConfig) -> Any:
    return r.weights.stall * (c.active & (c.moved_m < r.stall_distance_m)).sum(axis=-1)


def _energy_margin(c: SlotContext, r: RewardConfig) -> Any:
    stored, req = c.uplink_stored_j, c.uplink_req_j
    margin = np.tanh((stored - req) / (req + r.margin_epsilon_j))
    n_auvs = c.active.shape[-1]
    return r.weights.energy_margin / n_auvs * np.where(c.active, margin, 0).sum(-1)


def _infeasible_uplink(c: SlotContext, r: RewardConfig) -> Any:
    infeasible = c.active & (c.uplink_stored_j < c.uplink_req_j)
    return r.weights.infeasible_uplink * infeasible.sum(axis=-1)


def _collision(c: SlotContext, r: RewardConfig) -> Any:
    """The paper's Gaussian margin penalty below d_th, summed over pairs not both docked."""
    n = c.positions_m.shape[-2]
    if n < 2:
        return np.zeros(c.positions_m.shape[:-2])
    iu, ju = pair_indices(n)
    p = c.positions_m
    gap = np.maximum(0.0, r.safety_distance_m - norm_xy(p[..., iu, :] - p[..., ju, :]))
    pen = 1.0 - np.exp(-(gap**2) / (2 * r.collision_sigma_m**2))
    pen = np.where(c.docked[..., iu] & c.docked[..., ju], 0.0, pen)
    return r.weights.collision * pen.sum(axis=-1)


def _docking(c: SlotContext, r: RewardConfig) -> Any:
    w = r.weights
    return w.dock_first_entry * c.newly_docked.sum(axis=-1) + w.dock_all * c.all_docked_first


def _deadline(c: SlotContext, r: RewardConfig) -> Any:
    return r.weights.deadline * (c.slack_before_m - c.slack_m).sum(axis=-1)


def _undocked_at_end(c: SlotContext, r: RewardConfig) -> Any:
    return np.where(c.ending, r.weights.undocked_at_end * (~c.docked).sum(-1), 0.0)


def _aoi_after_mission(c: SlotContext, r: RewardConfig) -> Any:
    """Ending early does not stop the nodes' data from ageing: the AoI term of the slots left
    until T_max, with no more service, is booked when the episode ends."""
    return r.weights.aoi * c.aoi_after_mission


REWARD_FUNCTIONS: dict[str, Term] = {
    "docking_progress": _docking_progress,
    "aoi": _aoi,
    "fairness": _fairness,
    "boundary": _boundary,
    "stall": _stall,
    "energy_margin": _energy_margin,
    "infeasible_uplink": _infeasible_uplink,
    "collision": _collision,
    "docking": _docking,
    "deadline": _deadline,
    "undocked_at_end": _undocked_at_end,
    "aoi_after_mission": _aoi_after_mission,
}
REWARD_TERMS = tuple(REWARD_FUNCTIONS)


def reward_terms(c: SlotContext, r: RewardConfig) -> dict[str, Any]:
    """Every term of the slot, in the order of `REWARD_TERMS`."""
    return {name: term(c, r) for name, term in REWARD_FUNCTIONS.items()}
