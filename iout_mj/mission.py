"""Mission logic shared by both backends: actions, setpoints, network, reward, metrics (numpy).

A backend (the MuJoCo task or the kinematic model) only moves the vehicles and measures their
energy; everything the paper defines on top of the motion happens here, so both backends
compute AoI, harvest, reward and metrics the same way.

Decisions where the paper is open (see README, "Modelling decisions"):

- The action of slot t takes effect in slot t: theta_sp += dtheta, v_sp = clip(v_sp + dv, 0,
  V_max), then the vehicles move for one slot. (The paper's eq. 10 moves with the previous
  slot's theta and v: a one-slot delay.) Setpoints accumulate from setpoints, not from
  measurements, so both backends see the same heading sequence; headings are never wrapped
  inside the setpoint, so turning across +-pi is continuous.
- AET and uplink use the AUV-node distances at the end of the slot.
- Docked AUVs stay docked, stop (speed setpoint 0), neither charge nor collect, and the dock
  powers their hotel load (their battery pays nothing more).
- A move whose straight-line end point (from the slot's start position, with the new setpoints)
  leaves the area is an attempted boundary violation: penalised in both backends. The
  kinematic backend rejects the move (the paper); the MuJoCo backend has joint limits at the
  area's edges, a fence the vehicle stops against.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from dm_env import specs
from numpy.typing import NDArray

from iout_mj.config import Config, random_layout
from iout_mj.network import SensorNetwork, jain_index, pairwise_distance_m

FloatArray = NDArray[np.float64]
ACTION_FIELDS = ("heading", "speed", "aet_node", "uplink_node")
REWARD_TERMS = (
    "docking_progress",
    "aoi",
    "fairness",
    "boundary",
    "stall",
    "energy_margin",
    "infeasible_uplink",
    "collision",
    "docking",
    "deadline",
    "undocked_at_end",
    "aoi_after_mission",
)
COLLISION_DISTANCE_M = 5.0
"""Two hulls (3 m long) closer than this in a slot count as one collision (per pair and slot)."""
OBS_LOW, OBS_HIGH = -1.0, 2.0
"""Bounds of every observation entry (node energy is clipped to the top)."""
ENERGY_OBS_REF_J = 1e-3
"""Node energies are observed as log10(1 + e / 1 mJ) / 5 (1 mJ is a typical uplink need)."""


def _norm(v: FloatArray) -> FloatArray:
    """Length of each row of an (M, 2) array."""
    return np.hypot(v[:, 0], v[:, 1])


class ActionError(ValueError):
    """An action outside the action space."""


@dataclass
class MissionLog:
    """Per-slot history of one episode (for metrics, figures and rendering)."""

    positions_m: list[FloatArray] = field(default_factory=list)
    headings_rad: list[FloatArray] = field(default_factory=list)
    speeds_mps: list[FloatArray] = field(default_factory=list)
    mean_aoi: list[float] = field(default_factory=list)
    jain: list[float] = field(default_factory=list)
    aet_nodes: list[NDArray[np.int64]] = field(default_factory=list)
    uplink_nodes: list[NDArray[np.int64]] = field(default_factory=list)
    uplink_ok: list[NDArray[np.bool_]] = field(default_factory=list)


class Mission:
    """State and rules of one multi-AUV data-collection episode."""

    def __init__(self, cfg: Config, random_layout_per_episode: bool = False):
        self.cfg = cfg
        sc = cfg.scenario
        self.n_auvs = sc.n_auvs
        self.n_nodes = sc.n_nodes
        self.random_layout_per_episode = random_layout_per_episode
        self.area_m = np.asarray(sc.area_m, dtype=float)
        self.dock_m = np.asarray(sc.dock_center_m, dtype=float)
        self.network = SensorNetwork(sc.nodes_m, cfg.network, cfg.acoustics)
        m = cfg.motion
        self.dtheta_rad = np.radians(m.dtheta_max_deg) * (
            2 * np.arange(m.heading_levels) / (m.heading_levels - 1) - 1
        )
        self.dv_mps = m.dv_max_mps * (2 * np.arange(m.speed_levels) / (m.speed_levels - 1) - 1)
        self.action_high = np.tile(
            [m.heading_levels, m.speed_levels, self.n_nodes, self.n_nodes], self.n_auvs
        )
        iu, ju = np.triu_indices(self.n_auvs, k=1)
        self._pairs = (iu, ju)
        self._inv_area = 1.0 / self.area_m
        self._inv_diag = 1.0 / float(np.hypot(*self.area_m))
        self.log = MissionLog()

    # ------------------------------------------------------------------ episode
    def reset(self, rng: np.random.RandomState) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Start an episode; returns start positions (N, 2), headings and speeds."""
        sc, n = self.cfg.scenario, self.n_auvs
        if self.random_layout_per_episode:
            nodes = random_layout(self.n_nodes, int(rng.randint(2**31 - 1)), sc)
            self.network.nodes_m = np.asarray(nodes, dtype=float)
        self.network.reset()
        start = np.asarray(sc.starts_m[:n], dtype=float)
        start = start + rng.uniform(-1, 1, size=(n, 2)) * sc.start_jitter_m
        start = np.clip(start, 1.0, self.area_m - 1.0)
        heading = sc.start_heading_rad + rng.uniform(-1, 1, size=n) * np.radians(
            sc.start_heading_jitter_deg
        )
        speed = np.full(n, self.cfg.motion.initial_speed_mps)
        self.current_mps = np.asarray(self.cfg.physics.current_mps, dtype=float) + (
            rng.uniform(-1, 1, size=2) * self.cfg.physics.current_jitter_mps
        )
        self.heading_sp = heading.copy()
        self.speed_sp = speed.copy()
        self.positions_m = start.copy()
        self.headings_rad = heading.copy()
        self.speeds_mps = speed.copy()
        self.docked = np.zeros(n, dtype=bool)
        self.battery_j = np.full(n, self.cfg.motion.battery_j)
        self.propulsion_energy_j = np.zeros(n)
        self.yaw_energy_j = np.zeros(n)
        self.dock_dist_m = np.linalg.norm(start - self.dock_m, axis=1)
        self.deadline_slack_m = self._deadline_slack_m(self.dock_dist_m, 0)
        self.slot = 0
        self.sum_mean_aoi = 0.0
        self.sum_objective = 0.0
        self.aoi_after_mission = 0.0
        self.min_separation_m = np.inf
        self.collisions = 0
        self.all_docked_paid = False
        self.terms = dict.fromkeys(REWARD_TERMS, 0.0)
        self.reward = 0.0
        self.boundary_attempt = np.zeros(n, dtype=bool)
        self.outcome: Any = None
        self.log = MissionLog()
        self._log_slot(self.network.mean_aoi, self.network.jain)
        return start, heading, speed

    # ------------------------------------------------------------------ actions
    def decode(self, action: Any) -> NDArray[np.int64]:
        """Validate a flat action of 4 integers per AUV; returns an (N, 4) integer array."""
        a = np.asarray(action)
        if a.shape != self.action_high.shape:
            raise ActionError(
                f"action has shape {a.shape}; accepted a flat array of {self.action_high.size} "
                f"integers: (heading, speed, aet_node, uplink_node) for each of {self.n_auvs} "
                "AUVs"
            )
        integral = a.dtype.kind in "iu" or (
            a.dtype.kind == "f" and np.all(np.isfinite(a)) and np.all(a == np.round(a))
        )
        if not integral:
            raise ActionError(
                f"action {a.tolist()} has non-integer entries; accepted integer indices"
            )
        a = a.astype(np.int64)
        bad = (a < 0) | (a >= self.action_high)
        if bad.any():
            j = int(np.argmax(bad))
            auv, f = divmod(j, 4)
            raise ActionError(
                f"AUV {auv}: {ACTION_FIELDS[f]} index {int(a[j])} is out of "
                f"range; accepted 0 to {int(self.action_high[j]) - 1}"
            )
        return a.reshape(self.n_auvs, 4)

    def action_spec(self) -> specs.BoundedArray:
        """The dm_env action spec: 4 integer indices per AUV."""
        high = self.action_high
        return specs.BoundedArray(
            shape=high.shape,
            dtype=np.int64,
            minimum=np.zeros_like(high),
            maximum=high - 1,
            name="action",
        )

    def begin_slot(self, action: Any) -> tuple[FloatArray, FloatArray]:
        """Apply an action: new heading (unwrapped) and speed setpoints for every AUV."""
        a = self.decode(action)
        self.action = a
        moving = ~self.docked
        self.heading_sp = self.heading_sp + np.where(moving, self.dtheta_rad[a[:, 0]], 0.0)
        self.speed_sp = np.where(
            moving,
            np.clip(self.speed_sp + self.dv_mps[a[:, 1]], 0.0, self.cfg.motion.v_max_mps),
            0.0,
        )
        slot_s = self.cfg.scenario.slot_s
        step = (
            self.speed_sp[:, None]
            * slot_s
            * np.stack([np.cos(self.heading_sp), np.sin(self.heading_sp)], axis=1)
        )
        end = self.positions_m + step
        self.boundary_attempt = moving & np.any((end < 0) | (end > self.area_m), axis=1)
        return self.heading_sp, self.speed_sp

    def end_slot(
        self,
        positions_m: FloatArray,
        headings_rad: FloatArray,
        speeds_mps: FloatArray,
        propulsion_energy_j: FloatArray,
        yaw_energy_j: FloatArray,
        path_m: FloatArray,
    ) -> float:
        """Book one slot after the vehicles moved; returns the reward.

        Args:
            positions_m, headings_rad, speeds_mps: measured state at the end of the slot.
            propulsion_energy_j: (N,) electrical propulsion energy of the slot (no hotel load).
            yaw_energy_j: (N,) electrical yaw-actuation energy of the slot.
            path_m: (S, N, 2) positions during the slot (MuJoCo: every substep), for the
                separation metrics; pairs of docked AUVs (parked at the dock) are left out.
        """
        cfg, w = self.cfg, self.cfg.reward
        was_docked = self.docked
        moved_m = _norm(positions_m - self.positions_m)
        self.positions_m = positions_m
        self.headings_rad = headings_rad
        self.speeds_mps = speeds_mps
        hotel_j = np.where(was_docked, 0.0, cfg.motion.hotel_power_w * cfg.scenario.slot_s)
        self.propulsion_energy_j += propulsion_energy_j + hotel_j
        self.yaw_energy_j += yaw_energy_j
        self.battery_j -= propulsion_energy_j + yaw_energy_j + hotel_j

        active = ~was_docked
        out = self.network.step(positions_m, self.action[:, 2], self.action[:, 3], active)
        self.outcome = out
        dock_dist = _norm(positions_m - self.dock_m)
        self.docked = was_docked | (dock_dist <= cfg.scenario.dock_radius_m)
        newly = self.docked & ~was_docked

        mean_aoi = self.network.mean_aoi
        jain = self.network.jain
        delivered_total = int(self.network.deliveries.sum())
        t = self.terms
        progress_m = float(np.sum(self.dock_dist_m - dock_dist))
        t["docking_progress"] = w.docking_progress_per_m * progress_m
        t["aoi"] = -w.aoi * mean_aoi
        t["fairness"] = (
            -w.fairness * (1.0 - jain) if delivered_total > w.fairness_min_deliveries else 0.0
        )
        t["boundary"] = -w.boundary * float(self.boundary_attempt.sum())
        t["stall"] = -w.stall * float(np.sum(active & (moved_m < w.stall_distance_m)))
        margin = np.tanh(
            (out.uplink_stored_j - out.uplink_req_j) / (out.uplink_req_j + w.margin_epsilon_j)
        )
        t["energy_margin"] = w.energy_margin / self.n_auvs * float(np.sum(margin[active]))
        t["infeasible_uplink"] = -w.infeasible_uplink * float(
            np.sum(active & (out.uplink_stored_j < out.uplink_req_j))
        )
        t["collision"] = self._collision_term(positions_m)
        bonus = w.dock_first_entry * float(newly.sum())
        if self.docked.all() and not self.all_docked_paid:
            bonus += w.dock_all
            self.all_docked_paid = True
        t["docking"] = bonus
        slack = self._deadline_slack_m(dock_dist, self.slot + 1)
        t["deadline"] = w.deadline_per_m * float(np.sum(self.deadline_slack_m - slack))
        self.deadline_slack_m = slack
        ending = (
            self.docked.all()
            or (self.battery_j <= 0).any()
            or self.slot + 1 >= cfg.scenario.horizon_slots
        )
        t["undocked_at_end"] = -w.undocked_at_end * float((~self.docked).sum()) if ending else 0.0
        # Ending early does not stop the nodes' data from ageing: the AoI term of the slots
        # left until T_max, with no more service, is booked now (0 when the horizon is reached).
        self.aoi_after_mission = self._unserved_aoi_sum(self.slot + 1) if ending else 0.0
        t["aoi_after_mission"] = -w.aoi * self.aoi_after_mission
        self.reward = float(sum(t.values()))

        self.dock_dist_m = dock_dist
        self.slot += 1
        self.sum_mean_aoi += mean_aoi
        self.sum_objective += mean_aoi + w.fairness_lambda * (1.0 - jain)
        if self.n_auvs > 1:
            iu, ju = self._pairs
            gap = np.linalg.norm(path_m[:, iu] - path_m[:, ju], axis=2).min(axis=0)
            gap = gap[~(was_docked[iu] & was_docked[ju])]
            if gap.size:
                self.min_separation_m = min(self.min_separation_m, float(gap.min()))
                self.collisions += int(np.sum(gap < COLLISION_DISTANCE_M))
        self._log_slot(mean_aoi, jain)
        return self.reward

    def _unserved_aoi_sum(self, slot: int) -> float:
        """Sum over the slots left until T_max of the mean AoI if no node is served again."""
        left = self.cfg.scenario.horizon_slots - slot
        if left <= 0:
            return 0.0
        ages = np.minimum(
            self.network.aoi[None, :] + np.arange(1, left + 1)[:, None], self.cfg.network.aoi_max
        )
        return float(ages.mean(axis=1).sum())

    def _deadline_slack_m(self, dock_dist_m: FloatArray, slot: int) -> FloatArray:
        """How much farther from the dock each undocked AUV is than it can fly at v_ref in the
        time left (0 when on schedule or docked); its negative is the shaping potential."""
        sc, w = self.cfg.scenario, self.cfg.reward
        reach_m = w.deadline_speed_mps * (sc.horizon_slots - slot) * sc.slot_s
        return np.where(self.docked, 0.0, np.maximum(0.0, dock_dist_m - reach_m))

    def _collision_term(self, positions_m: FloatArray) -> float:
        if self.n_auvs < 2:
            return 0.0
        w = self.cfg.reward
        iu, ju = self._pairs
        d = _norm(positions_m[iu] - positions_m[ju])
        gap = np.maximum(0.0, w.safety_distance_m - d)
        pen = 1.0 - np.exp(-(gap**2) / (2 * w.collision_sigma_m**2))
        pen = np.where(self.docked[iu] & self.docked[ju], 0.0, pen)
        return -w.collision * float(pen.sum())

    def _log_slot(self, mean_aoi: float, jain: float) -> None:
        log = self.log
        log.positions_m.append(self.positions_m.copy())
        log.headings_rad.append(self.headings_rad.copy())
        log.speeds_mps.append(self.speeds_mps.copy())
        log.mean_aoi.append(mean_aoi)
        log.jain.append(jain)
        if self.outcome is not None:
            log.aet_nodes.append(self.action[:, 2].copy())
            log.uplink_nodes.append(self.action[:, 3].copy())
            log.uplink_ok.append(self.outcome.uplink_ok.copy())

    # ------------------------------------------------------------------ episode end
    @property
    def terminated(self) -> bool:
        """All docked, or a battery is empty."""
        return bool(self.docked.all() or (self.battery_j <= 0).any())

    @property
    def truncated(self) -> bool:
        return self.slot >= self.cfg.scenario.horizon_slots and not self.terminated

    def metrics(self) -> dict[str, Any]:
        """Episode metrics (time averages over the slots played so far)."""
        slots = max(self.slot, 1)
        return {
            "mean_aoi": self.sum_mean_aoi / slots,
            "mean_aoi_horizon": (self.sum_mean_aoi + self.aoi_after_mission)
            / max(self.slot, self.cfg.scenario.horizon_slots),
            "objective": self.sum_objective / slots,
            "jain": jain_index(self.network.deliveries),
            "delivered_bits": self.network.delivered_bits,
            "propulsion_energy_j": self.propulsion_energy_j.tolist(),
            "yaw_energy_j": self.yaw_energy_j.tolist(),
            "min_separation_m": (
                float(self.min_separation_m) if np.isfinite(self.min_separation_m) else None
            ),
            "docked": self.docked.tolist(),
            "mission_slots": self.slot,
            "collisions": self.collisions,
            "deliveries_per_node": self.network.deliveries.tolist(),
        }

    def trace(self) -> dict[str, Any]:
        """The episode's path and service, as plain lists (for figures and JSON)."""
        sc, net = self.cfg.scenario, self.network
        return {
            "positions_m": np.array(self.log.positions_m).tolist(),
            "headings_rad": np.array(self.log.headings_rad).tolist(),
            "speeds_mps": np.array(self.log.speeds_mps).tolist(),
            "nodes_m": net.nodes_m.tolist(),
            "delivered_bits_per_node": (net.deliveries * net.bits_per_delivery).tolist(),
            "dock_center_m": list(sc.dock_center_m),
            "dock_radius_m": sc.dock_radius_m,
            "area_m": list(sc.area_m),
            "slot_s": sc.slot_s,
        }

    # ------------------------------------------------------------------ observation
    def observation(self) -> dict[str, NDArray[np.float64]]:
        """The paper's state, scaled to about unit range (see `OBSERVATION_DOC`)."""
        sc = self.cfg.scenario
        d = (
            pairwise_distance_m(self.positions_m, self.network.nodes_m)
            if self.outcome is None
            else self.outcome.distance_m
        )  # end-of-slot distances
        return {
            "auv_position": (self.positions_m * self._inv_area).ravel(),
            "auv_heading": np.stack(
                [np.cos(self.headings_rad), np.sin(self.headings_rad)], axis=1
            ).ravel(),
            "auv_speed": self.speeds_mps / self.cfg.motion.v_max_mps,
            "docked": self.docked.astype(float),
            "aoi": self.network.aoi / self.cfg.network.aoi_max,
            "node_energy": np.minimum(
                np.log10(1 + self.network.energy_j / ENERGY_OBS_REF_J) / 5, OBS_HIGH
            ),
            "distance": (d * self._inv_diag).ravel(),
            "dock_distance": self.dock_dist_m * self._inv_diag,
            "time_remaining": np.array([1 - self.slot / sc.horizon_slots]),
        }

    def observation_sizes(self) -> dict[str, int]:
        n, k = self.n_auvs, self.n_nodes
        return {
            "auv_position": 2 * n,
            "auv_heading": 2 * n,
            "auv_speed": n,
            "docked": n,
            "aoi": k,
            "node_energy": k,
            "distance": n * k,
            "dock_distance": n,
            "time_remaining": 1,
        }


OBSERVATION_DOC = """\
Observation (flattened in this order; N AUVs, K nodes):
  auv_position   2N  (x, y) / area side                     [0, 1]
  auv_heading    2N  (cos, sin) of the measured heading      [-1, 1]
  auv_speed       N  measured speed over ground / V_max      [0, ~1]
  docked          N  1 once docked                           {0, 1}
  aoi             K  AoI / A_max                             (0, 1]
  node_energy     K  log10(1 + e / 1 mJ) / 5                 [0, ~1]
  distance      N*K  AUV-node distance / area diagonal       [0, 1]
  dock_distance   N  distance to dock centre / diagonal      [0, 1]
  time_remaining  1  1 - slot / T_max                        [0, 1]
The paper's state is positions, headings, speeds, AoI, node energies and distances; docked,
dock distance and remaining time are added because the docking deadline makes them part of
the Markov state.
"""
