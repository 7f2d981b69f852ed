"""The mission: the paper's rules on top of the motion, for one environment or a batch.

A backend (the MuJoCo task or the kinematic model) only moves the vehicles and measures their
energy; everything the paper defines on top of the motion happens here, so every backend
computes AoI, harvest, reward and metrics the same way. One `Mission` holds one environment
(`n_envs=None`: arrays (N, ...)) or B environments stepped together (`n_envs=B`: every array
gains a leading axis of B); the same code serves both.

A slot: `begin_slot(action)` sets the setpoints, the backend moves the vehicles, then
`end_slot(...)` books the measured motion and energy, steps the sensor network, and computes
the reward terms, termination and statistics. Decisions where the paper is open (README,
"Modelling decisions"): AET and uplink use the distances at the end of the slot; docked AUVs
stay docked, stop, neither charge nor collect, and the dock powers their hotel load; a move
whose straight-line end point leaves the area is a boundary attempt (penalised in every
backend).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from iout_mj.config import Config
from iout_mj.mission import stats
from iout_mj.mission.actions import ActionMap
from iout_mj.mission.observation import flatten_observation, observation_sizes, observe
from iout_mj.mission.rewards import REWARD_TERMS, SlotContext, reward_terms
from iout_mj.mission.state import MissionState
from iout_mj.scenarios import random_layout
from iout_mj.types import BoolArray, FloatArray
from iout_mj.world import propulsion
from iout_mj.world.geometry import norm_xy, pairwise_distance_m
from iout_mj.world.network import SensorNetwork, SlotOutcome, rows


class Mission:
    """State and rules of one multi-AUV data-collection episode, or of B of them at once.

    Longer than most classes here because `end_slot` is one ordered sequence (energy, network,
    docking, termination, reward, statistics) whose every rule lives in the module it calls.
    """

    cfg: Config
    state: MissionState
    network: SensorNetwork
    inv_area: FloatArray
    inv_diag: float

    def __init__(
        self, cfg: Config, random_layout_per_episode: bool = False, n_envs: int | None = None
    ):
        sc = cfg.scenario
        self.cfg = cfg
        self.n_auvs, self.n_nodes, self.n_envs = sc.n_auvs, sc.n_nodes, n_envs
        self.batch: tuple[int, ...] = () if n_envs is None else (n_envs,)
        self.random_layout_per_episode = random_layout_per_episode
        self.area_m = np.asarray(sc.area_m, dtype=float)
        self.dock_m = np.asarray(sc.dock_center_m, dtype=float)
        self.inv_area = 1.0 / self.area_m
        self.inv_diag = 1.0 / float(np.hypot(*self.area_m))
        self.actions = ActionMap(cfg, self.batch)
        self.network = SensorNetwork(sc.nodes_m, cfg.network, cfg.acoustics, self.batch)
        self.state = MissionState.zeros(self.batch, self.n_auvs, self.n_nodes)
        self.terms: dict[str, Any] = dict.fromkeys(REWARD_TERMS, np.zeros(self.batch))
        """The last slot's reward terms (arrays over the batch)."""
        self.outcome: SlotOutcome | None = None
        self.log = stats.MissionLog()

    @property
    def observation_sizes(self) -> dict[str, int]:
        return observation_sizes(self.n_auvs, self.n_nodes)

    # ------------------------------------------------------------------ episode
    def reset(self, rng: np.random.RandomState, mask: BoolArray | None = None) -> None:
        """Start an episode in every environment (mask None) or in those where `mask` is True.

        Random draws, in this order: node layouts (if random per episode), position jitter,
        heading jitter, current jitter; one row per restarted environment.
        """
        cfg, sc, n, s = self.cfg, self.cfg.scenario, self.n_auvs, self.state
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
        s.current_mps[i] = np.asarray(cfg.physics.current_mps, dtype=float) + (
            rng.uniform(-1, 1, size=(*count, 2)) * cfg.physics.current_jitter_mps
        )
        s.reset_rows(i)
        s.positions_m[i] = start
        s.straight_end_m[i] = start
        s.heading_sp[i] = heading
        s.headings_rad[i] = heading
        s.speed_sp[i] = cfg.motion.initial_speed_mps
        s.speeds_mps[i] = cfg.motion.initial_speed_mps
        s.battery_j[i] = cfg.motion.battery_j
        s.distance_m[i] = pairwise_distance_m(start, self.network.nodes_m[i])
        s.dock_dist_m[i] = norm_xy(start - self.dock_m)
        s.deadline_slack_m[i] = self._deadline_slack_m(s.dock_dist_m, s.slot)[i]
        if mask is None:  # a partial reset keeps the last step's reward for the finished rows
            s.reward[...] = 0.0
            self.terms = dict.fromkeys(REWARD_TERMS, np.zeros(self.batch))
            self.outcome = None
        if not self.batch:
            self.log = stats.MissionLog()
            self.log.record(s, self.network, None)

    # ------------------------------------------------------------------ slot
    def begin_slot(self, action: Any) -> tuple[FloatArray, FloatArray]:
        """Apply an action: new heading (unwrapped) and speed setpoints for every AUV."""
        self.actions.apply(self.state, self.actions.decode(action), self.area_m)
        return self.state.heading_sp, self.state.speed_sp

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
                the separation metrics.
        """
        cfg, sc, s, net = self.cfg, self.cfg.scenario, self.state, self.network
        was_docked = s.docked.copy()
        active = ~was_docked
        moved_m = norm_xy(positions_m - s.positions_m)
        s.positions_m[...] = positions_m
        s.headings_rad[...] = headings_rad
        s.speeds_mps[...] = speeds_mps
        hotel_j = np.where(was_docked, 0.0, propulsion.hotel_energy_j(sc.slot_s, cfg.motion))
        s.propulsion_energy_j += propulsion_energy_j + hotel_j
        s.yaw_energy_j += yaw_energy_j
        s.battery_j -= propulsion_energy_j + yaw_energy_j + hotel_j

        out = net.step(positions_m, s.action[..., 2], s.action[..., 3], active)
        self.outcome = out
        s.distance_m[...] = out.distance_m
        dock_dist = norm_xy(positions_m - self.dock_m)
        s.docked |= dock_dist <= sc.dock_radius_m
        all_docked = s.docked.all(axis=-1)
        all_docked_first = all_docked & ~s.all_docked_paid
        s.all_docked_paid |= all_docked
        s.slot += 1
        slack = self._deadline_slack_m(dock_dist, s.slot)
        s.terminated[...] = all_docked | (s.battery_j <= 0).any(axis=-1)
        s.truncated[...] = (s.slot >= sc.horizon_slots) & ~s.terminated
        ending = s.terminated | s.truncated
        s.aoi_after_mission[...] = (
            np.where(ending, stats.unserved_aoi_sum(cfg, s.slot, net.aoi), 0.0)
            if ending.any()
            else 0.0
        )
        mean_aoi, jain = net.mean_aoi, net.jain
        context = SlotContext(
            active=active,
            moved_m=moved_m,
            boundary_attempt=s.boundary_attempt,
            positions_m=positions_m,
            docked=s.docked,
            newly_docked=s.docked & active,
            all_docked_first=all_docked_first,
            dock_dist_before_m=s.dock_dist_m,
            dock_dist_m=dock_dist,
            slack_before_m=s.deadline_slack_m,
            slack_m=slack,
            mean_aoi=mean_aoi,
            jain=jain,
            deliveries=net.deliveries.sum(axis=-1),
            uplink_stored_j=out.uplink_stored_j,
            uplink_req_j=out.uplink_req_j,
            ending=ending,
            aoi_after_mission=s.aoi_after_mission,
        )
        self.terms = reward_terms(context, cfg.reward)
        s.reward[...] = sum(self.terms.values())
        s.deadline_slack_m[...] = slack
        s.dock_dist_m[...] = dock_dist
        s.sum_mean_aoi += mean_aoi
        s.sum_objective += mean_aoi + cfg.reward.fairness_lambda * (1.0 - jain)
        stats.book_separation(s, path_m, was_docked)
        if not self.batch:
            self.log.record(s, net, out.uplink_ok)
        return s.reward[()]

    def _deadline_slack_m(self, dock_dist_m: FloatArray, slot: Any) -> FloatArray:
        """How much farther from the dock each undocked AUV is than it can fly at v_ref in the
        time left (0 when on schedule or docked); its negative is the shaping potential."""
        sc, r = self.cfg.scenario, self.cfg.reward
        reach_m = r.deadline_speed_mps * (sc.horizon_slots - slot) * sc.slot_s
        return np.where(self.state.docked, 0.0, np.maximum(0.0, dock_dist_m - reach_m[..., None]))

    # ------------------------------------------------------------------ views
    def observation(self) -> dict[str, FloatArray]:
        """The observation groups, in their declared order (`mission.observation`)."""
        return observe(self)

    def flat_observation(self) -> np.ndarray:
        """`observation()` concatenated in order, as float32 (*batch, D)."""
        return flatten_observation(observe(self))

    def metrics(self, env: int | None = None) -> dict[str, Any]:
        """Episode metrics of one environment (`env` indexes the batch)."""
        if (env is None) != (not self.batch):
            raise ValueError(f"metrics(env={env}): give env only for a batch of environments")
        return stats.metrics(self.cfg, self.state, self.network, () if env is None else env)

    def trace(self) -> dict[str, Any]:
        """The episode's path and service (one env)."""
        return stats.trace(self.cfg, self.log, self.network)
