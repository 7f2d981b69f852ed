"""Stronger non-learning policies: the authors' communication-first baseline, and a tour
scheduler that a learned policy has to beat.

The tour scheduler rests on two facts. The link budget (README, "Acoustic link budget"): a
node passed at 50 m harvests about 12 J in one slot, while one uplink costs 0.1 J from 500 m;
so once every node has been charged at close range, every node can reach an AUV near the
middle of the area for the rest of the mission, and the AoI becomes a scheduling problem: N
deliveries per slot, a node's AoI resets after K_reset of them, and deliveries toward a reset
can be made early. And the schedule: a one-step rollout of those dynamics to the horizon is
near-optimal where every node can deliver (see `schedule_uplinks`).
"""

from __future__ import annotations

import itertools

import numpy as np

from iout_mj.agents.baselines import (
    CRUISE_MPS,
    NODE_REACHED_M,
    _must_dock,
    _pack,
    approach_speed,
    steer,
)
from iout_mj.mission import Mission
from iout_mj.types import BoolArray, FloatArray, IntArray
from iout_mj.world.geometry import pairwise_distance_m, wrap_angle

CHARGED_J = 1.0
"""A node holding this much is charged: about ten uplinks from 500 m (0.1 J each); more
charging on the tour cost more than it bought (tried 0.7 to 15 J on the kinematic backend)."""
UPLINK_MARGIN = 1.5
"""Uplink only from nodes holding this multiple of the need (the AUV moves in the slot)."""
MAX_CANDIDATES = 400
"""Assignments scored per slot at most (K = 20, N = 2 has 380)."""


def _greedy_tail_sum(
    aoi: FloatArray, count: IntArray, n: int, slots: int, k_reset: int, a_max: float
) -> FloatArray:
    """Sum of AoI over the next `slots` slots if every slot the n nodes with the highest
    a / (K_reset - c) deliver; for each row of a batch of states (C, K)."""
    aoi, count = aoi.copy(), count.copy()
    total = np.zeros(len(aoi))
    rows = np.arange(len(aoi))[:, None]
    for _ in range(slots):
        picks = np.argsort(-(aoi / (k_reset - count)), axis=1, kind="stable")[:, :n]
        count[rows, picks] += 1
        reset = count >= k_reset
        aoi = np.where(reset, 1.0, np.minimum(aoi + 1, a_max))
        count[reset] = 0
        total += aoi.sum(axis=1)
    return total


def schedule_uplinks(mission: Mission, positions_m: FloatArray) -> IntArray:
    """The uplink node of each AUV, by a one-step rollout of the AoI / K_reset dynamics to the
    horizon: every assignment of distinct nodes that can afford their uplinks (with a margin,
    the AUVs move during the slot) is scored by this slot's AoI plus the AoI of the slots left
    under the greedy schedule a / (K_reset - c), and the best is taken. Near-optimal where
    every node can always deliver (9.18 mean AoI over 55 slots for N = 1, K = 7, against 9.85
    for the greedy schedule alone)."""
    net, cfg = mission.network, mission.cfg
    k_reset, a_max = cfg.network.k_reset, cfg.network.aoi_max
    n = mission.n_auvs
    _, req = mission.link_energies_j(positions_m)
    can = net.energy_j[None, :] >= UPLINK_MARGIN * req  # (N, K)
    # With the channel's interference, uplinks of one slot drown each other (a node's power
    # gives SNR = gamma_req, 36 dB, at its AUV; a second node at a like range leaves SINR near
    # 0 dB): one node per slot, named by every AUV (one broadcast), as one lane.
    shared = cfg.channel.on("interference") and n > 1
    lanes = 1 if shared else n
    if shared:
        can = np.asarray(can.any(axis=0, keepdims=True))
    # candidate assignments: a node per lane, distinct, affordable (or a sure miss: -1); each
    # lane's options are its best few by the greedy gain, so that at most ~MAX_CANDIDATES
    gain = net.aoi / (k_reset - net.service_count)
    per_auv = max(lanes, int(MAX_CANDIDATES ** (1 / lanes)))
    options = []
    for i in range(lanes):
        nodes = np.flatnonzero(can[i])
        best_first = nodes[np.argsort(-gain[nodes], kind="stable")][:per_auv]
        options.append([int(x) for x in best_first] or [-1])
    # where no assignment of distinct nodes exists (more AUVs than affordable nodes), lanes
    # may also stay idle (-1), so that the others still uplink
    combos = _distinct(options) or _distinct([o if o == [-1] else [*o, -1] for o in options])
    picks = np.array(combos, dtype=np.int64)  # (C, lanes)
    aoi = np.repeat(net.aoi[None], len(picks), axis=0)
    count = np.repeat(net.service_count[None], len(picks), axis=0)
    rows = np.arange(len(picks))[:, None]
    np.add.at(count, (rows.repeat(lanes, 1)[picks >= 0], picks[picks >= 0]), 1)
    reset = count >= k_reset
    aoi = np.where(reset, 1.0, np.minimum(aoi + 1, a_max))
    count[reset] = 0
    left = int(cfg.scenario.horizon_slots - mission.state.slot - 1)
    value = aoi.sum(axis=1) + _greedy_tail_sum(aoi, count, lanes, max(left, 0), k_reset, a_max)
    best = picks[int(np.argmin(value))]
    if shared:
        best = np.full(n, best[0])
    cheapest = np.argmin(req, axis=1)
    return np.where(best >= 0, best, cheapest).astype(np.int64)


def _distinct(options: list[list[int]]) -> list[tuple[int, ...]]:
    """Every choice of one option per lane in which no node (>= 0) is named twice."""
    return [
        c
        for c in itertools.product(*options)
        if len({x for x in c if x >= 0}) == sum(x >= 0 for x in c)
    ]


def _dock_turn_rad(mission: Mission) -> FloatArray:
    """How far each AUV's heading setpoint is from the bearing to the dock (0 to pi)."""
    delta = mission.dock_m - mission.state.positions_m
    return np.abs(wrap_angle(np.arctan2(delta[:, 1], delta[:, 0]) - mission.state.heading_sp))


def _tour_order(start_m: FloatArray, nodes_m: FloatArray) -> list[int]:
    """Nearest-neighbour order of the nodes from a start point."""
    left, here, order = set(range(len(nodes_m))), start_m, []
    while left:
        nxt = min(left, key=lambda k: float(np.linalg.norm(nodes_m[k] - here)))
        order.append(nxt)
        left.remove(nxt)
        here = nodes_m[nxt]
    return order


LOITER_SPREAD_M = 120.0
"""Distance of each AUV's loiter point from the nodes' centroid (N > 1)."""
FINAL_STRETCH_M = 150.0
"""The last stretch to the dock zone, flown at FINAL_APPROACH_MPS."""
CURRENT_SPARE_SLOTS_PER_MPS = 6.0
"""Slots to spare at the docking decision per m/s of current (the drift while turning)."""
FINAL_APPROACH_MPS = 1.2
"""Speed of the last approach into the dock (a turning circle that fits the dock zone)."""


class TourScheduler:
    """Charge every node once at close range, early (the nodes split into one nearest-neighbour
    tour per AUV); then circle near the nodes' centroid, collecting, and fly into the dock at
    the last moment that still reaches it. Uplinks follow `schedule_uplinks` every slot."""

    name = "tour-scheduler"
    dock_spare_slots = 2.0
    """Slots to spare when deciding to head into the dock (a teacher for imitation may keep
    more, so that its pupil's timing errors do not make it late)."""
    top_approach_mps: float | None = None
    """Top speed of the approach into the dock; None: the final speed plus 1 m/s (the planner
    heads home from near the nodes' centroid)."""
    slow_turn_within_m = FINAL_STRETCH_M
    """Facing away from the dock within this distance, the approach turns slowly first (the
    planner never faces away from a far dock; a shielded policy may)."""

    def reset(self, seed: int | None = None) -> None:
        self._tours: list[list[int]] | None = None

    def _plan(self, mission: Mission) -> list[list[int]]:
        s, nodes = mission.state, mission.network.nodes_m
        order = _tour_order(s.positions_m.mean(axis=0), nodes)
        chunks = np.array_split(np.array(order), mission.n_auvs)
        # each chunk to the AUV whose start is nearest to the chunk's first node
        tours: list[list[int]] = [[] for _ in range(mission.n_auvs)]
        free = set(range(mission.n_auvs))
        for chunk in chunks:
            if len(chunk) == 0:
                continue
            i = min(free, key=lambda a: float(np.linalg.norm(s.positions_m[a] - nodes[chunk[0]])))
            tours[i] = [int(k) for k in chunk]
            free.discard(i)
        return tours

    def _loiter_points(self, mission: Mission) -> FloatArray:
        """One point per AUV, LOITER_SPREAD_M apart around the nodes' centroid (where the
        uplinks are cheapest), so that the AUVs keep apart."""
        centre = mission.network.nodes_m.mean(axis=0)
        angles = 2 * np.pi * np.arange(mission.n_auvs) / mission.n_auvs
        offsets = np.stack([np.cos(angles), np.sin(angles)], 1) * (mission.n_auvs > 1)
        return centre + LOITER_SPREAD_M * offsets

    def _waypoints(self, mission: Mission, targets_m: FloatArray) -> FloatArray:
        """Where each AUV steers on its way to its target: straight at it."""
        return targets_m

    @staticmethod
    def _final_speed(mission: Mission) -> float:
        """Speed of the final approach (over the ground): FINAL_APPROACH_MPS plus the
        current's speed, which leaves the current less time to push the AUV off its track
        (without it, in 1 m/s currents, both planners' mean AoI rose in 15 of 16 cells)."""
        return FINAL_APPROACH_MPS + float(np.hypot(*mission.state.current_mps))

    def must_dock(self, mission: Mission) -> BoolArray:
        """Head into the dock when the final approach (slowing to the final speed, turning,
        flying to the zone's edge at the ground speeds the current allows) takes all the slots
        left, with `dock_spare_slots` to spare."""
        s, m, slot_s = mission.state, mission.cfg.motion, mission.cfg.scenario.slot_s
        delta = mission.dock_m - s.positions_m
        turn = _dock_turn_rad(mission)
        turn_slots = np.ceil(turn / np.radians(m.dtheta_max_deg))
        final = self._final_speed(mission)
        slow_slots = np.maximum(s.speed_sp - final, 0) / m.dv_max_mps
        # the current along the way to the dock (against: negative)
        toward = delta / np.maximum(np.linalg.norm(delta, axis=1, keepdims=True), 1e-9)
        along = toward @ s.current_mps

        def ground(speed: float) -> FloatArray:
            """Speed over the ground toward the dock: the setpoint, the servo holds it (at
            most V_max through the water; crabbing drifts the current across away)."""
            return np.maximum(np.minimum(speed, m.v_max_mps + along), 0.1)

        edge_m = np.maximum(s.dock_dist_m - 0.6 * mission.cfg.scenario.dock_radius_m, 0)
        near_m = np.minimum(edge_m, FINAL_STRETCH_M)  # the last stretch, slowly
        travel_slots = (edge_m - near_m) / (ground(CRUISE_MPS) * slot_s) + near_m / (
            ground(final) * slot_s
        )
        left = mission.cfg.scenario.horizon_slots - s.slot
        # slots to spare, and more against a current (its drift while turning)
        spare = self.dock_spare_slots + CURRENT_SPARE_SLOTS_PER_MPS * float(
            np.hypot(*s.current_mps)
        )
        return turn_slots + slow_slots + travel_slots + spare >= left

    def dock_approach(self, mission: Mission) -> tuple[IntArray, IntArray]:
        """Heading and speed indices of every AUV's approach into the dock: cruise far away,
        the final speed near it, crabbing against the current; facing away from a near dock,
        a slow turn on a circle that fits the dock zone."""
        s = mission.state
        final = self._final_speed(mission)
        top = final + 1.0 if self.top_approach_mps is None else max(self.top_approach_mps, final)
        dock_speed = np.clip(approach_speed(s.dock_dist_m, mission.cfg.scenario.slot_s), final, top)
        tight = (_dock_turn_rad(mission) > 2 * np.radians(mission.cfg.motion.dtheta_max_deg)) & (
            s.dock_dist_m < self.slow_turn_within_m
        )
        dock_speed = np.where(tight, max(0.8, final - FINAL_APPROACH_MPS + 0.3), dock_speed)
        targets = np.broadcast_to(mission.dock_m, s.positions_m.shape)
        return steer(mission, targets, dock_speed, crab=True)

    def __call__(self, mission: Mission) -> IntArray:
        s, net = mission.state, mission.network
        if self._tours is None or s.slot == 0:
            self._tours = self._plan(mission)
        for tour in self._tours:
            while tour and net.energy_j[tour[0]] >= CHARGED_J:
                tour.pop(0)  # charged: on to the next node of the tour
        n, nodes, slot_s = mission.n_auvs, net.nodes_m, mission.cfg.scenario.slot_s
        touring = np.array([bool(t) for t in self._tours])
        loiter_at = self._loiter_points(mission)
        targets = np.array(
            [nodes[t[0]] if t else loiter_at[i] for i, t in enumerate(self._tours)], dtype=float
        ).reshape(n, 2)
        targets = self._waypoints(mission, targets)
        dist = np.linalg.norm(targets - s.positions_m, axis=1)
        speed = approach_speed(dist, slot_s)
        loiter = ~touring & (dist < 2 * NODE_REACHED_M)
        dock = self.must_dock(mission)
        h, sp = steer(mission, targets, np.where(loiter, 0.8, speed), crab=True)
        h = np.where(loiter, mission.cfg.motion.heading_levels - 1, h)  # circle
        dock_h, dock_sp = self.dock_approach(mission)
        h, sp = np.where(dock, dock_h, h), np.where(dock, dock_sp, sp)
        d = pairwise_distance_m(s.positions_m, nodes)
        wet = np.array([t[0] if t else 0 for t in self._tours], dtype=np.int64)
        wet = np.where(touring, wet, d.argmin(axis=1))
        return _pack(h, sp, wet, schedule_uplinks(mission, s.positions_m))


class CommunicationFirst:
    """The authors' communication-first baseline: while the mean AoI is above a threshold,
    each AUV flies to the node with the highest AoI (the AUVs take different nodes) and
    charges and collects from it; otherwise it heads for the dock (and always in time)."""

    name = "comm-first"
    AOI_THRESHOLD = 5.0
    """Mean AoI (slots) below which the AUVs head for the dock (the value is ours)."""

    def reset(self, seed: int | None = None) -> None:
        pass

    def __call__(self, mission: Mission) -> IntArray:
        s, net = mission.state, mission.network
        order = np.argsort(-net.aoi, kind="stable")
        node = order[np.arange(mission.n_auvs) % len(order)]
        go_dock = (net.mean_aoi <= self.AOI_THRESHOLD) | _must_dock(mission)
        targets = np.where(go_dock[..., None], mission.dock_m, net.nodes_m[node])
        dist = np.linalg.norm(targets - s.positions_m, axis=1)
        h, sp = steer(mission, targets, approach_speed(dist, mission.cfg.scenario.slot_s))
        return _pack(h, sp, node, node)
