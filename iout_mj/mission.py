"""Mission logic shared by both backends: actions, setpoints, network, reward, metrics (numpy).

A backend (the MuJoCo task or the kinematic model) only moves the vehicles and measures their
energy; everything the paper defines on top of the motion happens here, so both backends
compute AoI, harvest, reward and metrics the same way.

One `Mission` holds one environment (`n_envs=None`: arrays (N, ...), per-episode values 0-d)
or B environments stepped together (`n_envs=B`: every array gains a leading axis of B); the
same code serves both, so the batched kinematic backend and the MuJoCo task cannot drift apart.

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
from iout_mj.geometry import norm_xy, pairwise_distance_m, unit_xy
from iout_mj.network import SensorNetwork, jain_index, rows

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


class ActionError(ValueError):
    """An action outside the action space."""


@dataclass
class MissionLog:
    """Per-slot history of one episode (for metrics, figures and rendering; one env only)."""

    positions_m: list[FloatArray] = field(default_factory=list)
    headings_rad: list[FloatArray] = field(default_factory=list)
    speeds_mps: list[FloatArray] = field(default_factory=list)
    mean_aoi: list[float] = field(default_factory=list)
    jain: list[float] = field(default_factory=list)
    aet_nodes: list[NDArray[np.int64]] = field(default_factory=list)
    uplink_nodes: list[NDArray[np.int64]] = field(default_factory=list)
    uplink_ok: list[NDArray[np.bool_]] = field(default_factory=list)


class Mission:
    """State and rules of one multi-AUV data-collection episode, or of B of them at once.

    State is updated in place, so that `reset` can restart some environments of a batch.
    """

    def __init__(
        self, cfg: Config, random_layout_per_episode: bool = False, n_envs: int | None = None
    ):
        self.cfg = cfg
        sc = cfg.scenario
        n, k = sc.n_auvs, sc.n_nodes
        self.n_auvs, self.n_nodes = n, k
        self.n_envs = n_envs
        self.batch: tuple[int, ...] = () if n_envs is None else (n_envs,)
        b = self.batch
        self.random_layout_per_episode = random_layout_per_episode
        self.area_m = np.asarray(sc.area_m, dtype=float)
        self.dock_m = np.asarray(sc.dock_center_m, dtype=float)
        self.network = SensorNetwork(sc.nodes_m, cfg.network, cfg.acoustics, b)
        m = cfg.motion
        self.dtheta_rad = np.radians(m.dtheta_max_deg) * (
            2 * np.arange(m.heading_levels) / (m.heading_levels - 1) - 1
        )
        self.dv_mps = m.dv_max_mps * (2 * np.arange(m.speed_levels) / (m.speed_levels - 1) - 1)
        self.action_high = np.tile([m.heading_levels, m.speed_levels, k, k], n)
        self._pairs = np.triu_indices(n, k=1)
        self._inv_area = 1.0 / self.area_m
        self._inv_diag = 1.0 / float(np.hypot(*self.area_m))
        self._zero = np.zeros(b)
        self._v_max_mps = m.v_max_mps
        # Per AUV (*batch, N) and per environment (*batch,) state, reset by `reset`.
        self.positions_m = np.zeros((*b, n, 2))
        self.straight_end_m = np.zeros((*b, n, 2))
        """Where each AUV would end the slot flying straight with its new setpoints."""
        self.heading_sp = np.zeros((*b, n))
        self.speed_sp = np.zeros((*b, n))
        self.headings_rad = np.zeros((*b, n))
        self.speeds_mps = np.zeros((*b, n))
        self.docked = np.zeros((*b, n), dtype=bool)
        self.boundary_attempt = np.zeros((*b, n), dtype=bool)
        self.battery_j = np.zeros((*b, n))
        self.propulsion_energy_j = np.zeros((*b, n))
        self.yaw_energy_j = np.zeros((*b, n))
        self.dock_dist_m = np.zeros((*b, n))
        self.deadline_slack_m = np.zeros((*b, n))
        self.action = np.zeros((*b, n, 4), dtype=np.int64)
        self.distance_m = np.zeros((*b, n, k))
        """AUV-node distances at the end of the last slot (at the start after a reset)."""
        self.current_mps = np.zeros((*b, 2))
        self.slot = np.zeros(b, dtype=np.int64)
        self.sum_mean_aoi = np.zeros(b)
        self.sum_objective = np.zeros(b)
        self.aoi_after_mission = np.zeros(b)
        self.min_separation_m = np.full(b, np.inf)
        self.collisions = np.zeros(b, dtype=np.int64)
        self.all_docked_paid = np.zeros(b, dtype=bool)
        self.reward = np.zeros(b)
        self.terminated = np.zeros(b, dtype=bool)
        """All docked, or a battery is empty (set by `end_slot`)."""
        self.truncated = np.zeros(b, dtype=bool)
        """T_max reached without termination (set by `end_slot`)."""
        self.terms: dict[str, Any] = dict.fromkeys(REWARD_TERMS, self._zero)
        self.outcome: Any = None
        self.log = MissionLog()

    # ------------------------------------------------------------------ episode
    def reset(self, rng: np.random.RandomState, mask: NDArray[np.bool_] | None = None) -> None:
        """Start an episode in every environment (mask None) or in those where `mask` is True.

        Random draws, in this order: node layouts (if random per episode), position jitter,
        heading jitter, current jitter; one row per restarted environment.
        """
        sc, n = self.cfg.scenario, self.n_auvs
        i = rows(mask)
        count = () if not self.batch else (self.batch[0] if mask is None else int(mask.sum()),)
        if self.random_layout_per_episode:
            layouts = [
                random_layout(self.n_nodes, int(rng.randint(2**31 - 1)), sc)
                for _ in range(int(np.prod(count)))
            ]
            self.network.nodes_m[i] = np.reshape(layouts, (*count, self.n_nodes, 2))
        self.network.reset(mask)
        start = np.asarray(sc.starts_m[:n], dtype=float)
        start = start + rng.uniform(-1, 1, size=(*count, n, 2)) * sc.start_jitter_m
        start = np.clip(start, 1.0, self.area_m - 1.0)
        heading = sc.start_heading_rad + rng.uniform(-1, 1, size=(*count, n)) * np.radians(
            sc.start_heading_jitter_deg
        )
        self.current_mps[i] = np.asarray(self.cfg.physics.current_mps, dtype=float) + (
            rng.uniform(-1, 1, size=(*count, 2)) * self.cfg.physics.current_jitter_mps
        )
        self.positions_m[i] = start
        self.straight_end_m[i] = start
        self.heading_sp[i] = heading
        self.headings_rad[i] = heading
        self.speed_sp[i] = self.cfg.motion.initial_speed_mps
        self.speeds_mps[i] = self.cfg.motion.initial_speed_mps
        self.docked[i] = False
        self.boundary_attempt[i] = False
        self.battery_j[i] = self.cfg.motion.battery_j
        self.propulsion_energy_j[i] = 0.0
        self.yaw_energy_j[i] = 0.0
        self.action[i] = 0
        self.distance_m[i] = pairwise_distance_m(start, self.network.nodes_m[i])
        self.dock_dist_m[i] = norm_xy(start - self.dock_m)
        self.slot[i] = 0
        self.deadline_slack_m[i] = self._deadline_slack_m(self.dock_dist_m, self.slot)[i]
        self.sum_mean_aoi[i] = 0.0
        self.sum_objective[i] = 0.0
        self.aoi_after_mission[i] = 0.0
        self.min_separation_m[i] = np.inf
        self.collisions[i] = 0
        self.all_docked_paid[i] = False
        self.terminated[i] = False
        self.truncated[i] = False
        if mask is None:  # a partial reset keeps the last step's reward for the finished rows
            self.reward[...] = 0.0
            self.terms = dict.fromkeys(REWARD_TERMS, self._zero)
            self.outcome = None
        if not self.batch:
            self.log = MissionLog()
            self._log_slot(self.network.mean_aoi, self.network.jain)

    # ------------------------------------------------------------------ actions
    def decode(self, action: Any) -> NDArray[np.int64]:
        """Validate 4 integers per AUV (and a leading env axis when batched); returns
        (*batch, N, 4) indices."""
        a = np.asarray(action)
        shape = (*self.batch, self.action_high.size)
        if a.shape != shape:
            envs = f"{self.n_envs} rows (one per environment) of " if self.batch else "a flat "
            raise ActionError(
                f"action has shape {a.shape}; accepted {envs}{self.action_high.size} "
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
        a = a.astype(np.int64, copy=False)
        bad = (a < 0) | (a >= self.action_high)
        if bad.any():
            env, j = divmod(int(np.argmax(bad)), self.action_high.size)
            auv, f = divmod(j, 4)
            where = f"env {env}, " if self.batch else ""
            raise ActionError(
                f"{where}AUV {auv}: {ACTION_FIELDS[f]} index {int(a.flat[env * a.shape[-1] + j])} "
                f"is out of range; accepted 0 to {int(self.action_high[j]) - 1}"
            )
        return a.reshape(*self.batch, self.n_auvs, 4)

    def action_spec(self) -> specs.BoundedArray:
        """The dm_env action spec of one environment: 4 integer indices per AUV."""
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
        self.action[...] = a
        moving = ~self.docked
        self.heading_sp += np.where(moving, self.dtheta_rad[a[..., 0]], 0.0)
        self.speed_sp[...] = np.where(
            moving,
            np.minimum(np.maximum(self.speed_sp + self.dv_mps[a[..., 1]], 0.0), self._v_max_mps),
            0.0,
        )
        step_m = (self.speed_sp * self.cfg.scenario.slot_s)[..., None] * unit_xy(self.heading_sp)
        self.straight_end_m[...] = self.positions_m + step_m
        end = self.straight_end_m
        self.boundary_attempt[...] = moving & ((end < 0) | (end > self.area_m)).any(axis=-1)
        return self.heading_sp, self.speed_sp

    def end_slot(
        self,
        positions_m: FloatArray,
        headings_rad: FloatArray,
        speeds_mps: FloatArray,
        propulsion_energy_j: FloatArray,
        yaw_energy_j: FloatArray,
        path_m: FloatArray,
    ) -> Any:
        """Book one slot after the vehicles moved; returns the reward (*batch,).

        Args:
            positions_m, headings_rad, speeds_mps: measured state at the end of the slot.
            propulsion_energy_j: (*batch, N) electrical propulsion energy of the slot (no
                hotel load).
            yaw_energy_j: (*batch, N) electrical yaw-actuation energy of the slot.
            path_m: (S, *batch, N, 2) positions during the slot (MuJoCo: every substep), for
                the separation metrics; pairs of docked AUVs (parked at the dock) are left out.
        """
        cfg, w, sc = self.cfg, self.cfg.reward, self.cfg.scenario
        was_docked = self.docked.copy()
        active = ~was_docked
        moved_m = norm_xy(positions_m - self.positions_m)
        self.positions_m[...] = positions_m
        self.headings_rad[...] = headings_rad
        self.speeds_mps[...] = speeds_mps
        hotel_j = np.where(was_docked, 0.0, cfg.motion.hotel_power_w * sc.slot_s)
        self.propulsion_energy_j += propulsion_energy_j + hotel_j
        self.yaw_energy_j += yaw_energy_j
        self.battery_j -= propulsion_energy_j + yaw_energy_j + hotel_j

        net = self.network
        out = net.step(positions_m, self.action[..., 2], self.action[..., 3], active)
        self.outcome = out
        self.distance_m[...] = out.distance_m
        dock_dist = norm_xy(positions_m - self.dock_m)
        self.docked |= dock_dist <= sc.dock_radius_m
        newly = self.docked & active
        all_docked = self.docked.all(axis=-1)

        mean_aoi, jain = net.mean_aoi, net.jain
        t = {}
        t["docking_progress"] = w.docking_progress_per_m * (self.dock_dist_m - dock_dist).sum(-1)
        t["aoi"] = -w.aoi * mean_aoi
        served = net.deliveries.sum(axis=-1) > w.fairness_min_deliveries
        t["fairness"] = np.where(served, -w.fairness * (1.0 - jain), 0.0)
        t["boundary"] = -w.boundary * self.boundary_attempt.sum(axis=-1)
        t["stall"] = -w.stall * (active & (moved_m < w.stall_distance_m)).sum(axis=-1)
        stored, req = out.uplink_stored_j, out.uplink_req_j
        margin = np.tanh((stored - req) / (req + w.margin_epsilon_j))
        t["energy_margin"] = w.energy_margin / self.n_auvs * np.where(active, margin, 0).sum(-1)
        t["infeasible_uplink"] = -w.infeasible_uplink * (active & (stored < req)).sum(axis=-1)
        t["collision"] = self._collision_term(positions_m)
        t["docking"] = w.dock_first_entry * newly.sum(axis=-1) + w.dock_all * (
            all_docked & ~self.all_docked_paid
        )
        self.all_docked_paid |= all_docked
        self.slot += 1
        slack = self._deadline_slack_m(dock_dist, self.slot)
        t["deadline"] = w.deadline_per_m * (self.deadline_slack_m - slack).sum(axis=-1)
        self.deadline_slack_m[...] = slack
        self.terminated[...] = all_docked | (self.battery_j <= 0).any(axis=-1)
        self.truncated[...] = (self.slot >= sc.horizon_slots) & ~self.terminated
        ending = self.terminated | self.truncated
        t["undocked_at_end"] = np.where(ending, -w.undocked_at_end * (~self.docked).sum(-1), 0.0)
        # Ending early does not stop the nodes' data from ageing: the AoI term of the slots
        # left until T_max, with no more service, is booked now (0 when the horizon is reached).
        self.aoi_after_mission[...] = (
            np.where(ending, self._unserved_aoi_sum(), 0.0) if ending.any() else 0.0
        )
        t["aoi_after_mission"] = -w.aoi * self.aoi_after_mission
        self.terms = t
        self.reward[...] = sum(t.values())

        self.dock_dist_m[...] = dock_dist
        self.sum_mean_aoi += mean_aoi
        self.sum_objective += mean_aoi + w.fairness_lambda * (1.0 - jain)
        if self.n_auvs > 1:
            iu, ju = self._pairs
            gap = norm_xy(path_m[..., iu, :] - path_m[..., ju, :]).min(axis=0)
            gap = np.where(was_docked[..., iu] & was_docked[..., ju], np.inf, gap)
            np.minimum(self.min_separation_m, gap.min(axis=-1), out=self.min_separation_m)
            self.collisions += (gap < COLLISION_DISTANCE_M).sum(axis=-1)
        if not self.batch:
            self._log_slot(mean_aoi, jain)
        return self.reward[()]

    def _unserved_aoi_sum(self) -> FloatArray:
        """Sum over the slots left until T_max of the mean AoI if no node is served again:
        sum_{j=1..L} min(a + j, A_max) per node, in closed form."""
        a_max = self.cfg.network.aoi_max
        left = np.maximum(self.cfg.scenario.horizon_slots - self.slot, 0)[..., None]
        a = self.network.aoi
        rising = np.clip(np.floor(a_max - a), 0, left)  # slots before the cap is reached
        total = rising * a + rising * (rising + 1) / 2 + (left - rising) * a_max
        return total.mean(axis=-1)

    def _deadline_slack_m(self, dock_dist_m: FloatArray, slot: NDArray[np.int64]) -> FloatArray:
        """How much farther from the dock each undocked AUV is than it can fly at v_ref in the
        time left (0 when on schedule or docked); its negative is the shaping potential."""
        sc, w = self.cfg.scenario, self.cfg.reward
        reach_m = w.deadline_speed_mps * (sc.horizon_slots - slot) * sc.slot_s
        return np.where(self.docked, 0.0, np.maximum(0.0, dock_dist_m - reach_m[..., None]))

    def _collision_term(self, positions_m: FloatArray) -> Any:
        """The paper's Gaussian margin penalty, summed over pairs not both docked."""
        if self.n_auvs < 2:
            return self._zero
        w = self.cfg.reward
        iu, ju = self._pairs
        gap = np.maximum(
            0.0, w.safety_distance_m - norm_xy(positions_m[..., iu, :] - positions_m[..., ju, :])
        )
        pen = 1.0 - np.exp(-(gap**2) / (2 * w.collision_sigma_m**2))
        pen = np.where(self.docked[..., iu] & self.docked[..., ju], 0.0, pen)
        return -w.collision * pen.sum(axis=-1)

    def _log_slot(self, mean_aoi: float, jain: float) -> None:
        log = self.log
        log.positions_m.append(self.positions_m.copy())
        log.headings_rad.append(self.headings_rad.copy())
        log.speeds_mps.append(self.speeds_mps.copy())
        log.mean_aoi.append(float(mean_aoi))
        log.jain.append(float(jain))
        if self.outcome is not None:
            log.aet_nodes.append(self.action[:, 2].copy())
            log.uplink_nodes.append(self.action[:, 3].copy())
            log.uplink_ok.append(self.outcome.uplink_ok.copy())

    # ------------------------------------------------------------------ episode end
    def metrics(self, env: int | None = None) -> dict[str, Any]:
        """Episode metrics of one environment (`env` indexes the batch; time averages over the
        slots played so far)."""
        if (env is None) != (not self.batch):
            raise ValueError(f"metrics(env={env}): give env only for a batch of environments")
        i: Any = () if env is None else env
        slot = int(self.slot[i])
        slots = max(slot, 1)
        min_sep = float(self.min_separation_m[i])
        return {
            "mean_aoi": float(self.sum_mean_aoi[i]) / slots,
            "mean_aoi_horizon": float(self.sum_mean_aoi[i] + self.aoi_after_mission[i])
            / max(slot, self.cfg.scenario.horizon_slots),
            "objective": float(self.sum_objective[i]) / slots,
            "jain": float(jain_index(self.network.deliveries[i])),
            "delivered_bits": float(self.network.delivered_bits[i]),
            "propulsion_energy_j": self.propulsion_energy_j[i].tolist(),
            "yaw_energy_j": self.yaw_energy_j[i].tolist(),
            "min_separation_m": min_sep if np.isfinite(min_sep) else None,
            "docked": self.docked[i].tolist(),
            "mission_slots": slot,
            "collisions": int(self.collisions[i]),
            "deliveries_per_node": self.network.deliveries[i].tolist(),
        }

    def trace(self) -> dict[str, Any]:
        """The episode's path and service, as plain lists (for figures and JSON; one env)."""
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
    def observation(self) -> dict[str, FloatArray]:
        """The paper's state, scaled to about unit range (see `OBSERVATION_DOC`)."""
        b = self.batch
        return {
            "auv_position": (self.positions_m * self._inv_area).reshape(*b, -1),
            "auv_heading": unit_xy(self.headings_rad).reshape(*b, -1),
            "auv_speed": self.speeds_mps / self.cfg.motion.v_max_mps,
            "docked": self.docked.astype(float),
            "aoi": self.network.aoi / self.cfg.network.aoi_max,
            "node_energy": np.minimum(
                np.log10(1 + self.network.energy_j / ENERGY_OBS_REF_J) / 5, OBS_HIGH
            ),
            "distance": (self.distance_m * self._inv_diag).reshape(*b, -1),
            "dock_distance": self.dock_dist_m * self._inv_diag,
            "time_remaining": (1 - self.slot / self.cfg.scenario.horizon_slots)[..., None],
        }

    def flat_observation(self) -> NDArray[np.float32]:
        """`observation()` concatenated in its documented order, as float32 (*batch, D)."""
        return flatten_observation(self.observation())

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


def flatten_observation(obs: dict[str, FloatArray]) -> NDArray[np.float32]:
    """An observation dict concatenated in its (documented) order, as float32 (..., D)."""
    return np.concatenate(list(obs.values()), axis=-1, dtype=np.float32)


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
