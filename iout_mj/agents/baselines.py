"""Non-learning policies: greedy (the paper's), round-robin, random-walk and a deadline planner.

Each policy maps the env's public mission state (`env.unwrapped.mission`, a `Mission`) to a
valid flat action for any N and K: `policy(mission) -> np.ndarray`. The observation alone
would do for most of them, but reading the mission's named arrays keeps them exact and simple.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from iout_mj.mission import Mission
from iout_mj.types import BoolArray, FloatArray, IntArray
from iout_mj.world.geometry import pairwise_distance_m, slot_velocity_mps, wrap_angle

NODE_REACHED_M = 60.0
"""A node is 'being visited' within this distance."""
CRUISE_MPS = 3.0
DOCK_MARGIN_SLOTS = 6.0


class Policy(Protocol):
    name: str

    def reset(self, seed: int | None = None) -> None: ...

    def __call__(self, mission: Mission) -> IntArray: ...


def steer(
    mission: Mission, targets_m: FloatArray, speeds_mps: FloatArray, crab: bool = False
) -> tuple[IntArray, IntArray]:
    """Heading and speed indices that turn each AUV toward its target and toward a speed;
    with `crab` in a current, the heading index whose move over the ground at the slot's speed
    setpoint (the kinematic model, `slot_velocity_mps`) points closest at the target."""
    s, a = mission.state, mission.actions
    dv = speeds_mps - s.speed_sp
    speed_index = np.abs(a.dv_mps[None, :] - dv[:, None]).argmin(axis=1)
    delta = targets_m - s.positions_m
    want = np.arctan2(delta[:, 1], delta[:, 0])
    if crab and np.any(s.current_mps):
        v_max_mps = mission.cfg.motion.v_max_mps
        speed = np.clip(s.speed_sp + a.dv_mps[speed_index], 0.0, v_max_mps)  # the slot's setpoint
        headings = s.heading_sp[:, None] + a.dtheta_rad[None, :]
        ground = slot_velocity_mps(headings, speed[:, None], s.current_mps, v_max_mps)
        track = np.arctan2(ground[..., 1], ground[..., 0])
        return np.abs(wrap_angle(track - want[:, None])).argmin(axis=1), speed_index
    dtheta = wrap_angle(want - s.heading_sp)
    return np.abs(a.dtheta_rad[None, :] - dtheta[:, None]).argmin(axis=1), speed_index


def approach_speed(distance_m: FloatArray, slot_s: float) -> FloatArray:
    """Cruise far away, slow down near the target so the turning circle fits (>= 0.8 m/s)."""
    return np.clip(distance_m / (4.0 * slot_s), 0.8, CRUISE_MPS)


def _slots_left(mission: Mission) -> float:
    return float(mission.cfg.scenario.horizon_slots - mission.state.slot)


def _must_dock(mission: Mission, extra_m: FloatArray | float = 0.0) -> BoolArray:
    """AUVs that must head for the dock now to arrive before the horizon: travel at cruise
    speed, plus the slots to turn toward the dock and to ramp up to cruise speed."""
    m = mission.cfg.motion
    slot_m = CRUISE_MPS * mission.cfg.scenario.slot_s
    delta = mission.dock_m - mission.state.positions_m
    turn = np.abs(wrap_angle(np.arctan2(delta[:, 1], delta[:, 0]) - mission.state.heading_sp))
    turn_slots = turn / np.radians(m.dtheta_max_deg)
    ramp_slots = np.maximum(CRUISE_MPS - mission.state.speed_sp, 0) / m.dv_max_mps
    travel = (
        mission.state.dock_dist_m + extra_m - mission.cfg.scenario.dock_radius_m * 0.5
    ) / slot_m
    return travel + turn_slots + ramp_slots + DOCK_MARGIN_SLOTS >= _slots_left(mission)


def _pack(h: IntArray, s: IntArray, wet: IntArray, data: IntArray) -> IntArray:
    return np.stack([h, s, wet, data], axis=1).ravel().astype(np.int64)


class Greedy:
    """The paper's baseline: fly to the dock, arriving at the horizon; AET to the closest
    node; uplink by round robin, independent of motion."""

    name = "greedy"

    def reset(self, seed: int | None = None) -> None:
        pass

    def __call__(self, mission: Mission) -> IntArray:
        n, k = mission.n_auvs, mission.n_nodes
        slot_s = mission.cfg.scenario.slot_s
        remaining_s = max(_slots_left(mission) - 1, 1) * slot_s
        speed = np.clip(mission.state.dock_dist_m / remaining_s, 0.4, mission.cfg.motion.v_max_mps)
        targets = np.tile(mission.dock_m, (n, 1))
        h, s = steer(mission, targets, speed)
        d = pairwise_distance_m(mission.state.positions_m, mission.network.nodes_m)
        wet = d.argmin(axis=1)
        data = (mission.state.slot * n + np.arange(n)) % k
        return _pack(h, s, wet, data)


class RoundRobin:
    """Visits the nodes in a fixed cyclic order (AUV i takes nodes i, i+N, ...), charging and
    collecting from the node it visits, and docks in time."""

    name = "round-robin"

    def reset(self, seed: int | None = None) -> None:
        self._next: IntArray | None = None

    def __call__(self, mission: Mission) -> IntArray:
        n, k = mission.n_auvs, mission.n_nodes
        if self._next is None or mission.state.slot == 0:
            self._next = np.arange(n) % k
        nodes = mission.network.nodes_m
        reached = (
            np.linalg.norm(nodes[self._next] - mission.state.positions_m, axis=1) < NODE_REACHED_M
        )
        self._next = np.where(reached, (self._next + n) % k, self._next)
        targets = nodes[self._next]
        dock = _must_dock(mission)
        targets = np.where(dock[:, None], mission.dock_m, targets)
        dist = np.linalg.norm(targets - mission.state.positions_m, axis=1)
        h, s = steer(mission, targets, approach_speed(dist, mission.cfg.scenario.slot_s))
        return _pack(h, s, self._next, self._next)


class RandomWalk:
    """Uniformly random heading/speed increments and node choices (seeded)."""

    name = "random-walk"

    def __init__(self, seed: int | None = 0):
        self.reset(seed)

    def reset(self, seed: int | None = None) -> None:
        self._rng = np.random.default_rng(seed)

    def __call__(self, mission: Mission) -> IntArray:
        return self._rng.integers(0, mission.actions.high).astype(np.int64)


class Planner:
    """Deadline-aware AoI planner.

    Every slot each AUV (in turn, excluding nodes the others already took) heads for the node
    with the best AoI gain per slot of travel, among nodes it can still visit and then reach the
    dock before the horizon; it stays at a node (circling) until its AoI resets. It charges the
    node it heads for and collects from the feasible node with the highest AoI.
    """

    name = "planner"

    def reset(self, seed: int | None = None) -> None:
        self._target: IntArray | None = None

    def __call__(self, mission: Mission) -> IntArray:
        n, _k = mission.n_auvs, mission.n_nodes
        net = mission.network
        nodes = net.nodes_m
        slot_m = CRUISE_MPS * mission.cfg.scenario.slot_s
        if self._target is None or mission.state.slot == 0:
            self._target = np.full(n, -1)
        d = pairwise_distance_m(mission.state.positions_m, nodes)  # (N, K)
        node_to_dock = np.linalg.norm(nodes - mission.dock_m, axis=1)
        left = _slots_left(mission)
        taken: set[int] = set()
        target = self._target.copy()
        for i in range(n):
            t = int(target[i])
            if t >= 0 and (net.aoi[t] <= 1.0 or t in taken):
                t = -1  # served (AoI reset) or claimed by another AUV
            if t < 0:
                travel = d[i] / slot_m
                feasible = travel + 1 + node_to_dock / slot_m + DOCK_MARGIN_SLOTS < left
                score = (net.aoi + 1) / (travel + mission.cfg.network.k_reset)
                score[~feasible] = -np.inf
                for j in taken:
                    score[j] = -np.inf
                t = int(score.argmax()) if np.isfinite(score).any() else -1
            target[i] = t
            if t >= 0:
                taken.add(t)
        self._target = target
        go_dock = (target < 0) | _must_dock(mission)
        safe_t = np.maximum(target, 0)
        dist_t = d[np.arange(n), safe_t]
        targets = np.where(go_dock[:, None], mission.dock_m, nodes[safe_t])
        near = ~go_dock & (dist_t < NODE_REACHED_M)
        dist = np.where(go_dock, mission.state.dock_dist_m, dist_t)
        speed = np.where(near, 0.8, approach_speed(dist, mission.cfg.scenario.slot_s))
        h, s = steer(mission, targets, speed)
        h = np.where(near, mission.cfg.motion.heading_levels - 1, h)  # circle at the node
        _, req = mission.link_energies_j(mission.state.positions_m)  # the rules' own budget
        can = net.energy_j[None, :] >= req
        data = np.empty(n, dtype=np.int64)
        chosen: set[int] = set()
        for i in range(n):
            score = np.where(can[i], net.aoi, -1.0) - 1e-6 * d[i]
            for j in chosen:
                score[j] = -np.inf
            data[i] = int(score.argmax())
            chosen.add(int(data[i]))
        wet = np.where(go_dock, d.argmin(axis=1), safe_t)
        return _pack(h, s, wet, data)
