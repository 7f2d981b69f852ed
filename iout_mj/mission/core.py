"""The mission: the paper's rules on top of the motion, for one environment or a batch.

A backend (the MuJoCo task or the kinematic model) only moves the vehicles and measures their
energy; everything the paper defines on top of the motion happens in the compiled rules
(`mission.rules`), so every backend computes AoI, harvest, reward and metrics with the same
code. One `Mission` holds one environment (`n_envs=None`: arrays (N, ...)) or B environments
stepped together (`n_envs=B`: every array gains a leading axis of B); the rules see both as a
batch (one env: of one).

A slot: `begin_slot(action)` sets the setpoints, the backend moves the vehicles, then
`end_slot(...)` books the measured motion and energy, steps the sensor network, and computes
the reward terms, termination and statistics. Decisions where the paper is open (README,
"Modelling decisions"): AET and uplink use the distances at the end of the slot; docked AUVs
stay docked, stop, neither charge nor collect, and the dock powers their hotel load; a move
whose straight-line end point leaves the area is a boundary attempt (penalised in every
backend).
"""

from __future__ import annotations

import ctypes
from typing import Any

import numpy as np

from iout_mj import native
from iout_mj.config import Config
from iout_mj.mission import rules, stats
from iout_mj.mission.actions import ActionMap
from iout_mj.mission.observation import observation_sizes, split_observation
from iout_mj.mission.rewards import REWARD_TERMS
from iout_mj.mission.state import MissionLog, MissionState
from iout_mj.mission.tokens import ETA_CRUISE_MPS, K_MAX, token_size
from iout_mj.scenarios import random_layout
from iout_mj.types import BoolArray, FloatArray
from iout_mj.world.geometry import pairwise_distance_m
from iout_mj.world.network import SensorNetwork, rows
from iout_mj.world.tl_table import TLTableError


def channel_draws_per_auv(n_auvs: int) -> int:
    """Uniforms per AUV and slot (native.h's IOUT_CHANNEL_DRAWS): the packet draw, then 4 per
    transmitter (fading, shadowing)."""
    return 1 + 4 * n_auvs


def constant(values: list[float]) -> FloatArray:
    """`values` in an array the compiled rules may read (`native.allocate`)."""
    out = native.allocate((len(values),), float)
    out[:] = values
    return out


class Mission(native.Frozen):
    """State and rules of one multi-AUV data-collection episode, or of B of them at once.

    The compiled rules point into the state, log, network, constants and slot buffers of a
    mission (its private `_view`), so none of its attributes can be rebound (`native.Frozen`):
    state is written in place, and every C call checks sizes, slots and indices first.
    """

    cfg: Config
    state: MissionState
    network: SensorNetwork
    log: MissionLog
    inv_area: FloatArray
    inv_diag: float
    auv_depth_m: FloatArray
    node_depth_m: FloatArray

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
        self.actions = ActionMap(cfg, self.batch)
        self.network = SensorNetwork(
            sc.nodes_m, cfg.network, cfg.acoustics, self.batch, channel=cfg.channel
        )
        self.state = MissionState.zeros(self.batch, self.n_auvs, self.n_nodes)
        self.log = MissionLog.zeros(self.batch, self.n_auvs, sc.horizon_slots)
        """Per-slot history of the episode (`MissionLog`)."""
        self.params = rules.params(cfg)
        """The config's constants for the rules, a read-only (1,) record of
        `rules.PARAMS_DTYPE`."""
        self.inv_diag = float(self.params["inv_diag_per_m"][0])
        auv_m, node_m = cfg.channel.depths_m(self.n_auvs, self.n_nodes)
        self.auv_depth_m = native.read_only(constant(auv_m))
        """(N,) each AUV's depth in the link budgets (zeros with the channel's depth off)."""
        self.node_depth_m = native.read_only(constant(node_m))
        """(K,) each node's seabed depth in the link budgets (zeros with depth off)."""
        self._check_table_reach()
        self.term_values = native.allocate((*(self.batch or (1,)), len(REWARD_TERMS)), float)
        """The last slot's reward terms, (B, terms) in the order of REWARD_TERMS."""
        self._bind()
        self._freeze()

    def _check_table_reach(self) -> None:
        """Refuse a transmission-loss table that ends short of the area's diagonal (beyond its
        last range it would hold the last TL)."""
        link = self.network.link
        if not link.has_table:
            return
        c = link.constants[0]
        last_m, diagonal_m = (
            float(c["tl_range_m"][c["tl_ranges"] - 1]),
            float(np.hypot(*self.area_m)),
        )
        if last_m < diagonal_m:
            raise TLTableError(
                f"transmission_loss_file {self.cfg.channel.transmission_loss_file} reaches "
                f"{last_m:g} m, short of the area's diagonal ({diagonal_m:.1f} m): accepted a "
                "table over every horizontal range in the area (`iout-mj tl-table "
                "--max-range-m`)"
            )

    def link_energies_j(self, positions_m: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(harvest per charging period, uplink E_req), (*batch, N, K), of AUVs at
        `positions_m` (*batch, N, 2) with the nodes, at the mission's depths: the compiled link
        budget the slot rules apply (slant ranges, or the transmission-loss table)."""
        horizontal = pairwise_distance_m(positions_m, self.network.nodes_m)
        return self.network.link.energies_j(
            horizontal, self.auv_depth_m[:, None], self.node_depth_m[None, :]
        )

    def _bind(self) -> None:
        """The rules' view of this mission: the arrays with a batch axis, the slot's buffers,
        and the C struct of pointers (rebuilt after unpickling: it holds addresses)."""
        b, n = self.batch or (1,), self.n_auvs
        self._arrays = self.state.arrays(bool(self.batch))
        """The state with a batch axis always (one env: of one), as the rules see it."""
        self._log_arrays = self.log.arrays(bool(self.batch))
        shapes = {
            "actions": (*b, n, 4),
            "end_positions_m": (*b, n, 2),
            "end_headings_rad": (*b, n),
            "end_speeds_mps": (*b, n),
            "propulsion_energy_j": (*b, n),
            "yaw_energy_j": (*b, n),
            "path_m": (0, *b, n, 2),
            "obs": (*b, sum(self.observation_sizes.values())),
            "channel_draws": (*b, n, channel_draws_per_auv(n)),
            "link_sinr_db": (*b, n),
            "link_per": (*b, n),
            "link_packets_sent": (*b, n),
            "link_packets_received": (*b, n),
        }
        self._inputs = {k: native.allocate(shapes[k], rules.INPUTS[k]) for k in shapes}
        """The slot's buffers that the rules share with Python (`rules.INPUTS`)."""
        self._inputs["terms"] = self.term_values
        view = rules.MissionView(
            n_envs=b[0],
            n_auvs=n,
            n_nodes=self.n_nodes,
            horizon_slots=self.cfg.scenario.horizon_slots,
            heading_levels=self.actions.dtheta_rad.size,
            speed_levels=self.actions.dv_mps.size,
            n_obs=shapes["obs"][-1],
            n_path=0,
            net=self.network._struct,
        )
        constants = {
            "p": self.params,
            "link": self.network.link.constants,
            "channel": self.network.channel.constants,
            "dtheta_rad": self.actions.dtheta_rad,
            "dv_mps": self.actions.dv_mps,
            "auv_depth_m": self.auv_depth_m,
            "node_depth_m": self.node_depth_m,
        }
        native.fill(view, {**constants, **self._inputs})
        native.fill(view.s, self._arrays)
        native.fill(view.log, self._log_arrays)
        self._view = view
        self._view_address = ctypes.addressof(view)
        """The address of `_view`, the one argument of the compiled slot functions."""
        self._all_rows = np.ones(b, dtype=bool)

    def __getstate__(self) -> dict[str, Any]:
        derived = ("_arrays", "_log_arrays", "_inputs", "_view", "_view_address", "_all_rows")
        return {k: v for k, v in self.__dict__.items() if k not in derived}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._bind()

    @property
    def observation_sizes(self) -> dict[str, int]:
        return observation_sizes(self.n_auvs, self.n_nodes)

    @property
    def terms(self) -> dict[str, Any]:
        """The last slot's reward terms by name (arrays over the batch; numbers for one env)."""
        if self.batch:
            return dict(zip(REWARD_TERMS, self.term_values.T.copy(), strict=True))
        return dict(zip(REWARD_TERMS, self.term_values[0].tolist(), strict=True))

    # ------------------------------------------------------------------ episode
    def reset(self, rng: np.random.RandomState, mask: BoolArray | None = None) -> None:
        """Start an episode in every environment (mask None) or in those where `mask` is True.

        Random draws, in this order: node layouts (if random per episode), position jitter,
        heading jitter, current jitter; one row per restarted environment. `rng` is the task
        RNG: with channel packets or fading on, every slot draws its uniforms from it too.
        """
        self._random = rng
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
        if mask is None:  # a partial reset keeps the last step's reward for the finished rows
            s.reward[...] = 0.0
            self.term_values[...] = 0.0
        restarted = self._all_rows if mask is None else np.ascontiguousarray(mask, dtype=bool)
        if restarted.shape != self._all_rows.shape:
            raise ValueError(
                f"reset mask of shape {restarted.shape}; accepted {self._all_rows.shape}"
            )
        native.call(native.lib.iout_start, self._view_address, native.address(restarted))

    # ------------------------------------------------------------------ slot
    def begin_slot(self, action: Any) -> tuple[FloatArray, FloatArray]:
        """Apply an action: new heading (unwrapped) and speed setpoints for every AUV."""
        self.set_actions(action)
        native.call(native.lib.iout_begin_slot, self._view_address)
        return self.state.heading_sp, self.state.speed_sp

    def set_actions(self, action: Any) -> None:
        """Check an action's shape (`ActionMap.decode`) and hand it to the rules (which check
        its ranges before they use it)."""
        self._inputs["actions"].reshape(-1)[:] = self.actions.decode(action).reshape(-1)
        if self.network.channel.draws:
            self._draw_channel()

    def _draw_channel(self) -> None:
        """The slot's uniforms for the channel (packets, fading), from the task RNG of the
        last `reset`: one call, (*batch, N, IOUT_CHANNEL_DRAWS(N)) values."""
        draws = self._inputs["channel_draws"]
        random = getattr(self, "_random", None)
        if random is None:
            raise RuntimeError("the channel draws from the task RNG: call reset() first")
        draws.reshape(-1)[:] = random.random_sample(draws.size)

    def channel_info(self) -> dict[str, Any] | None:
        """The last slot's uplinks through the channel, per AUV (arrays over the batch; lists
        for one env): `sinr_db` and `per` of the link from the node it collects from (NaN: no
        transmission reached it), `packets_sent` by that node and `packets_received` of them
        (at any AUV); None on the paper's channel."""
        if not self.network.channel.enabled:
            return None
        x = self._inputs
        names = {
            "sinr_db": "link_sinr_db",
            "per": "link_per",
            "packets_sent": "link_packets_sent",
            "packets_received": "link_packets_received",
        }
        if self.batch:
            return {k: x[v].copy() for k, v in names.items()}
        return {k: x[v][0].tolist() for k, v in names.items()}

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
        n, b, x = self.n_auvs, self.batch or (1,), self._inputs
        path = np.asarray(path_m, dtype=float).reshape(len(path_m), *b, n, 2)
        if path.shape != x["path_m"].shape:  # the backend's points per slot
            x["path_m"] = native.allocate(path.shape, float)
            self._view.path_m, self._view.n_path = native.address(x["path_m"]), len(path)
        x["path_m"][...] = path
        x["end_positions_m"][...] = np.reshape(positions_m, (*b, n, 2))
        x["end_headings_rad"][...] = np.reshape(headings_rad, (*b, n))
        x["end_speeds_mps"][...] = np.reshape(speeds_mps, (*b, n))
        x["propulsion_energy_j"][...] = np.reshape(propulsion_energy_j, (*b, n))
        x["yaw_energy_j"][...] = np.reshape(yaw_energy_j, (*b, n))
        native.call(native.lib.iout_end_slot, self._view_address)
        return self.state.reward[()]

    # ------------------------------------------------------------------ views
    def observe(self) -> FloatArray:
        """The flat observation of every environment, (B, D) float64 (one env: B = 1)."""
        native.call(native.lib.iout_observe, self._view_address)
        obs: FloatArray = self._inputs["obs"]
        return obs

    def observe_tokens(self, k_max: int = K_MAX) -> np.ndarray:
        """The token observation of every environment (`mission.tokens`), float32
        (*batch, token_size(N, k_max)); raises NativeError if K > k_max."""
        out = np.empty((*(self.batch or (1,)), token_size(self.n_auvs, k_max)), np.float32)
        native.call(
            native.lib.iout_observe_tokens,
            self._view_address,
            int(k_max),
            ETA_CRUISE_MPS,
            native.address(out),
            out.size,
        )
        return out if self.batch else out[0]

    def observation(self) -> dict[str, FloatArray]:
        """The observation groups, in their declared order (`mission.observation`)."""
        flat = self.observe() if self.batch else self.observe()[0]
        return {k: v.copy() for k, v in split_observation(flat, self.n_auvs, self.n_nodes).items()}

    def flat_observation(self) -> np.ndarray:
        """The observation groups concatenated in order, as float32 (*batch, D)."""
        flat = self.observe()
        return flat.astype(np.float32) if self.batch else flat[0].astype(np.float32)

    def metrics(self, env: int | None = None) -> dict[str, Any]:
        """Episode metrics of one environment (`env` indexes the batch)."""
        if (env is None) != (not self.batch):
            raise ValueError(f"metrics(env={env}): give env only for a batch of environments")
        return stats.metrics(self.cfg, self.state, self.network, () if env is None else env)

    def trace(self) -> dict[str, Any]:
        """The episode's path and service (one env)."""
        return stats.trace(self.cfg, self.log, self.network, int(self.state.slot))
