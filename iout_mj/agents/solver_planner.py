"""A solver-grade baseline: the charging tours from a vehicle-routing solver (PyVRP), flown with
the tour scheduler's uplink schedule, loitering and docking timed to the deadline.

The routing problem: N vehicles, each from its own start, every node visited once by one of
them, all ending at the dock; each route within the slot budget (T_max slots at cruise speed,
the leg into the dock included); minimise the longest route, then the total. In the objective
a route ends at the nodes' centroid, not at the dock: after its last node an AUV loiters near
the centroid until the docking decision (with no cost on the last leg, some tours ended far
out and 3 of 40 missions with N = 1, K = 20 did not dock in time; this way none failed).

Why PyVRP: it states this problem directly (a depot per start, a common end depot, a route
length limit and a duration limit per vehicle type), its wheel is 1.2 MB and needs nothing the
project does not have (numpy, matplotlib, tqdm; vrplib), and a solve of K = 30, N = 4 takes
tens of milliseconds. OR-Tools routing states the problem as directly (with a makespan cost),
but its wheel is 30 MB and needs protobuf < 6.34, older than the one installed here; elkai
(LKH-3) solves one TSP, so N vehicles need the classic transformation into one tour, and
LKH's licence is for academic use. PyVRP minimises a sum, so the longest route is minimised
by bisection on the vehicles' route length limit.

A solve is seeded and limited by iterations, not time, so a layout and start always give the
same tours; a policy solves once per episode, at its first slot.
"""

from __future__ import annotations

import numpy as np
import pyvrp
from pyvrp.stop import MaxIterations

from iout_mj.agents.baselines import CRUISE_MPS, approach_speed
from iout_mj.agents.planners import TourScheduler
from iout_mj.mission import Mission
from iout_mj.types import FloatArray
from iout_mj.world.geometry import slot_velocity_mps, wrap_angle

SOLVER_ITERATIONS = 50
"""Iterations of PyVRP's search per solve: 150 or 400 found the same tours in all but one of
20 random layouts (N = 1 to 4, K = 11 to 30), at 3 and 8 times the time."""
BISECTION_STEPS = 5
"""Solves that bisect the longest route after the first, unconstrained one (N > 1)."""
BISECTION_TOLERANCE = 0.02
"""Stop bisecting when the bounds on the longest route are this close (relative)."""
DOCK_CLEARANCE_M = 50.0
"""Tours and flights keep this far outside the dock zone (entering it docks an AUV for good)."""
DETOUR_FACTOR = np.sqrt(2.0)
"""A detour waypoint lies this multiple of the clearance radius from the dock's centre."""
LOOKAHEAD_SLOTS = 8
"""Slots of flight predicted to check that turning toward a target keeps out of the dock zone
(a half turn at 25 deg per slot takes 7.2; the turning circle at cruise speed is ~170 m)."""
TRACK_MARGIN_M = 30.0
"""A predicted track must keep this far outside the dock zone."""
ESCAPE_M = 300.0
"""Distance of the escape targets (along the dock circle's tangents, or straight away)."""


def dock_waypoints(
    from_m: FloatArray, to_m: FloatArray, dock_m: FloatArray, clear_m: float
) -> FloatArray:
    """Per row, where to head on the way from `from_m` to `to_m` (both (M, 2)): `to_m` itself,
    or, where the straight leg passes closer than `clear_m` to the dock's centre, a waypoint
    beside the dock on the side of the leg's closest point."""
    leg = to_m - from_m
    length2 = np.maximum(np.einsum("ij,ij->i", leg, leg), 1e-9)
    t = np.clip(np.einsum("ij,ij->i", dock_m - from_m, leg) / length2, 0.0, 1.0)
    closest = from_m + t[:, None] * leg
    off = closest - dock_m
    off_m = np.linalg.norm(off, axis=1)
    # the leg runs through the centre: go round on its left
    left = np.stack([-leg[:, 1], leg[:, 0]], axis=1) / np.sqrt(length2)[:, None]
    side = np.where(off_m[:, None] > 1e-6, off / np.maximum(off_m, 1e-9)[:, None], left)
    detour = dock_m + DETOUR_FACTOR * clear_m * side
    return np.where((off_m < clear_m)[:, None], detour, to_m)


def leg_lengths_m(points_m: FloatArray, dock_m: FloatArray, clear_m: float) -> FloatArray:
    """Length of the flight between every pair of points (P, P), round the dock where the
    straight leg would cross its zone."""
    p = len(points_m)
    a = np.repeat(points_m, p, axis=0)
    b = np.tile(points_m, (p, 1))
    via = dock_waypoints(a, b, dock_m, clear_m)
    length = np.linalg.norm(via - a, axis=1) + np.linalg.norm(b - via, axis=1)
    return length.reshape(p, p)


def _problem(
    starts_m: FloatArray, nodes_m: FloatArray, dock_m: FloatArray, clear_m: float, budget_m: float
) -> pyvrp.ProblemData:
    """The routing problem: a vehicle type per AUV, from its start (depot i) to the dock (depot
    N); the nodes are the clients. Distances and durations in metres; a leg into the dock has
    the distance to the nodes' centroid (the objective) and its own length as its duration
    (the budget)."""
    n = len(starts_m)
    points = np.concatenate([starts_m, dock_m[None], nodes_m])
    legs = leg_lengths_m(points, dock_m, clear_m)
    legs[:, n] = np.linalg.norm(points - dock_m, axis=1)  # into the dock: straight in
    legs = np.rint(legs).astype(int)
    # in the objective, a route ends where its AUV goes after its tour: near the centroid
    to_station = np.rint(np.linalg.norm(points - nodes_m.mean(axis=0), axis=1)).astype(int)
    model = pyvrp.Model()
    locations = [model.add_location(x=float(x), y=float(y)) for x, y in points]
    depots = [model.add_depot(location) for location in locations[: n + 1]]
    for i in range(n):
        model.add_vehicle_type(
            1, start_depot=depots[i], end_depot=depots[n], shift_duration=int(budget_m)
        )
    for location in locations[n + 1 :]:
        model.add_client(location)
    for a, frm in enumerate(locations):
        for b, to in enumerate(locations):
            if a != b:
                model.add_edge(
                    frm, to, distance=to_station[a] if b == n else legs[a, b], duration=legs[a, b]
                )
    return model.data()


def _solve(
    data: pyvrp.ProblemData, seed: int, longest_m: int | None = None
) -> tuple[list[list[int]], pyvrp.Solution]:
    """Each AUV's nodes in visiting order, and the solution; with `longest_m`, every route's
    distance limited to it."""
    if longest_m is not None:
        limited = [v.replace(max_distance=longest_m) for v in data.vehicle_types()]
        data = data.replace(vehicle_types=limited)
    best = pyvrp.solve(data, MaxIterations(SOLVER_ITERATIONS), seed=seed, collect_stats=False).best
    tours: list[list[int]] = [[] for _ in range(data.num_vehicle_types)]
    for route in best.routes():
        tours[route.vehicle_type()] = [a.idx for a in route.schedule() if a.is_client()]
    return tours, best


def _longest_m(solution: pyvrp.Solution) -> int:
    return max((route.distance() for route in solution.routes()), default=0)


def solve_tours(
    starts_m: FloatArray,
    nodes_m: FloatArray,
    dock_m: FloatArray,
    clear_m: float,
    budget_m: float,
    seed: int = 0,
) -> list[list[int]]:
    """The nodes of each AUV in visiting order (every node in exactly one tour), from the AUVs'
    starts (N, 2) to the dock, by PyVRP: the longest route (to the nodes' centroid) is
    bisected down (N > 1), then the total is minimised under it."""
    data = _problem(starts_m, nodes_m, dock_m, clear_m, budget_m)
    tours, best = _solve(data, seed)
    if len(starts_m) == 1:
        return tours
    budget_ok = not best.has_time_warp()
    # the longest route is at least the way to the farthest node from its nearest start
    low = float(np.linalg.norm(nodes_m[:, None] - starts_m[None], axis=2).min(axis=1).max())
    high = float(_longest_m(best))
    for _ in range(BISECTION_STEPS):
        if high - low <= BISECTION_TOLERANCE * high:
            break
        limit = int((low + high) / 2)
        candidate, solution = _solve(data, seed, limit)
        if solution.has_excess_distance() or (budget_ok and solution.has_time_warp()):
            low = limit
        else:
            tours, high = candidate, float(_longest_m(solution))
    return tours


class SolverTour(TourScheduler):
    """The tour scheduler with its charging tours from a routing solver (`solve_tours`), and
    flights that go round the dock zone instead of through it."""

    name = "solver-tour"

    def _clear_m(self, mission: Mission) -> float:
        return mission.cfg.scenario.dock_radius_m + DOCK_CLEARANCE_M

    def _plan(self, mission: Mission) -> list[list[int]]:
        sc = mission.cfg.scenario
        budget_m = sc.horizon_slots * sc.slot_s * CRUISE_MPS
        return solve_tours(
            mission.state.positions_m,
            mission.network.nodes_m,
            mission.dock_m,
            self._clear_m(mission),
            budget_m,
        )

    def _waypoints(self, mission: Mission, targets_m: FloatArray) -> FloatArray:
        """Round the dock zone: the target, or a detour waypoint beside the dock where the
        straight leg crosses its clearance; and where turning toward that would still sweep
        into the zone (the turning circle), the first escape target whose predicted track
        keeps out: along either tangent of the dock circle, or straight away."""
        pos, dock = mission.state.positions_m, mission.dock_m
        way = dock_waypoints(pos, targets_m, dock, self._clear_m(mission))
        out = pos - dock
        radial = out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-9)
        tangent = np.stack([-radial[:, 1], radial[:, 0]], axis=1)
        lo = np.full(2, TRACK_MARGIN_M)
        hi = np.asarray(mission.cfg.scenario.area_m) - TRACK_MARGIN_M
        candidates = [way] + [
            np.clip(pos + ESCAPE_M * d, lo, hi) for d in (tangent, -tangent, radial)
        ]
        clearance = np.stack([_track_clearance_m(mission, c) for c in candidates])  # (C, N)
        keep_out = mission.cfg.scenario.dock_radius_m + TRACK_MARGIN_M
        first_clear = np.argmax(clearance >= keep_out, axis=0)
        choice = np.where(
            (clearance >= keep_out).any(axis=0), first_clear, clearance.argmax(axis=0)
        )
        return np.stack(candidates)[choice, np.arange(len(pos))]


def _track_clearance_m(mission: Mission, targets_m: FloatArray) -> FloatArray:
    """The closest each AUV comes to the dock's centre over the next LOOKAHEAD_SLOTS slots if
    it turns toward its target as fast as it may and speeds toward the approach speed
    (setpoints take effect in their slot; each slot moves it as the kinematic backend does)."""
    s, m, slot_s = mission.state, mission.cfg.motion, mission.cfg.scenario.slot_s
    pos, heading, speed = s.positions_m.copy(), s.heading_sp.copy(), s.speed_sp.copy()
    turn_rad = np.radians(m.dtheta_max_deg)
    closest = np.linalg.norm(pos - mission.dock_m, axis=1)
    for _ in range(LOOKAHEAD_SLOTS):
        delta = targets_m - pos
        want = np.arctan2(delta[:, 1], delta[:, 0])
        heading = heading + np.clip(wrap_angle(want - heading), -turn_rad, turn_rad)
        goal = approach_speed(np.linalg.norm(delta, axis=1), slot_s)
        speed = np.clip(speed + np.clip(goal - speed, -m.dv_max_mps, m.dv_max_mps), 0, None)
        pos = pos + slot_velocity_mps(heading, speed, s.current_mps, m.v_max_mps) * slot_s
        closest = np.minimum(closest, np.linalg.norm(pos - mission.dock_m, axis=1))
    return closest
