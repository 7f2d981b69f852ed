"""Typed, frozen configuration of a mission, with the paper's defaults and their sources.

One frozen dataclass per section, each with its checks beside its fields, so that the
parameter table and its validation read together (hence the module's length).
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from iout_mj.paper import DEFAULT_STARTS, PAPER_LAYOUTS, Point
from iout_mj.schema import (
    ConfigError,
    build_dataclass,
    check_finite,
    fraction,
    load_mapping,
    positive,
    require,
    to_plain,
)

MAX_AUVS = 4
MIN_NODES, MAX_NODES = 2, 30


@dataclass(frozen=True)
class MotionConfig:
    """Vehicle motion and propulsion (paper Table I, plus battery from the authors' code)."""

    v_max_mps: float = 4.0
    drag_coefficient: float = 0.006
    """C_d, dimensionless, referred to the wetted area."""
    wetted_area_m2: float = 3.0
    prop_efficiency: float = 0.7
    water_density_kgpm3: float = 1000.0
    hotel_power_w: float = 40.0
    dtheta_max_deg: float = 25.0
    dv_max_mps: float = 0.4
    heading_levels: int = 11
    speed_levels: int = 7
    initial_speed_mps: float = 1.0
    battery_j: float = 2.0e6

    def __post_init__(self) -> None:
        check_finite(self)
        positive(
            self,
            "v_max_mps",
            "drag_coefficient",
            "wetted_area_m2",
            "water_density_kgpm3",
            "dtheta_max_deg",
            "dv_max_mps",
            "battery_j",
        )
        fraction(self, "prop_efficiency")
        require(self.hotel_power_w >= 0, "hotel_power_w", self.hotel_power_w, "a number >= 0")
        for name in ("heading_levels", "speed_levels"):
            value = getattr(self, name)
            require(
                value >= 3 and value % 2 == 1,
                name,
                value,
                "an odd integer >= 3 (so that the middle level is 'no change')",
            )
        require(
            0 <= self.initial_speed_mps <= self.v_max_mps,
            "initial_speed_mps",
            self.initial_speed_mps,
            f"a speed in [0, v_max_mps={self.v_max_mps}]",
        )

    @property
    def drag_factor_nspm2(self) -> float:
        """rho * C_d * S / 2 in N s^2/m^2: steady surge drag is this times v^2."""
        return 0.5 * self.water_density_kgpm3 * self.drag_coefficient * self.wetted_area_m2


@dataclass(frozen=True)
class AcousticsConfig:
    """Acoustic energy transfer and uplink (paper Table II, open values from the authors' code)."""

    f_wet_khz: float = 70.0
    f_data_khz: float = 50.0
    p_tx_w: float = 5.0
    """Electrical power of the AUV's AET projector."""
    eta_tx: float = 0.7
    di_tx_db: float = 10.0
    di_rx_db: float = 10.0
    spreading_factor: float = 1.5
    rvs_db: float = -150.0
    """Receiving voltage sensitivity, dB re 1 V/uPa."""
    load_resistance_ohm: float = 125.0
    n_hydrophones: int = 4
    eta_harv: float = 0.7
    bandwidth_hz: float = 1000.0
    data_rate_bps: float = 12000.0
    charging_s: float = 25.0
    data_s: float = 25.0
    noise_model: str = "flat"
    """'flat' (a constant spectral level) or 'wenz' (turbulence, shipping, wind, thermal)."""
    noise_level_db: float = 40.0
    """Flat ambient noise spectral level, dB re 1 uPa^2/Hz."""
    shipping_activity: float = 0.5
    """Wenz model shipping activity in [0, 1]."""
    wind_speed_mps: float = 0.0
    """Wenz model surface wind speed."""

    def __post_init__(self) -> None:
        check_finite(self)
        positive(
            self,
            "f_wet_khz",
            "f_data_khz",
            "p_tx_w",
            "spreading_factor",
            "load_resistance_ohm",
            "bandwidth_hz",
            "data_rate_bps",
            "charging_s",
            "data_s",
        )
        fraction(self, "eta_tx", "eta_harv")
        require(self.n_hydrophones >= 1, "n_hydrophones", self.n_hydrophones, "an integer >= 1")
        require(
            self.noise_model in ("flat", "wenz"),
            "noise_model",
            self.noise_model,
            "'flat' or 'wenz'",
        )
        require(
            0 <= self.shipping_activity <= 1,
            "shipping_activity",
            self.shipping_activity,
            "a number in [0, 1]",
        )
        require(self.wind_speed_mps >= 0, "wind_speed_mps", self.wind_speed_mps, "a number >= 0")


@dataclass(frozen=True)
class NetworkConfig:
    """Sensor-node state rules (paper section III-A; open values from the authors' code)."""

    k_reset: int = 3
    aoi_max: float = 50.0
    node_initial_energy_j: float = 0.1

    def __post_init__(self) -> None:
        check_finite(self)
        require(self.k_reset >= 1, "k_reset", self.k_reset, "an integer >= 1")
        require(self.aoi_max >= 1, "aoi_max", self.aoi_max, "a number >= 1")
        require(
            self.node_initial_energy_j >= 0,
            "node_initial_energy_j",
            self.node_initial_energy_j,
            "a number >= 0",
        )


@dataclass(frozen=True)
class RewardWeights:
    """Signed scale of each reward term (`mission.rewards`): reward = sum of weight x quantity.

    Values from the authors' code except where noted; a negative weight is a cost.
    """

    docking_progress: float = 0.02
    """alpha_g, per metre closer to the dock; the paper gives no value: 0.02 makes a full
    approach worth about 22."""
    aoi: float = -0.1
    """Per unit of mean AoI, every slot (and for the unserved slots after an early end)."""
    fairness: float = -2.0
    """Per unit of (1 - Jain's index)."""
    boundary: float = -20.0
    """Per AUV whose move would leave the area."""
    stall: float = -1.0
    """Per active AUV that moved less than `stall_distance_m`."""
    energy_margin: float = 2.0
    """Shared by the AUVs: tanh of the uplink energy margin of the node each collects from."""
    infeasible_uplink: float = -0.02
    """Per active AUV whose uplink node cannot afford the transmission."""
    collision: float = -4.0
    """alpha_c, per pair: the Gaussian margin penalty below d_th."""
    dock_first_entry: float = 60.0
    """Per AUV, the slot it first enters the dock."""
    dock_all: float = 10.0
    """Once, the slot the last AUV docks."""
    deadline: float = 0.1
    """Deadline shaping (ours), per metre of the potential -max(0, d_dock - v_ref t_left)."""
    undocked_at_end: float = -100.0
    """Per AUV not docked when the episode ends: the terminal constraint (12a), l_n(T) in G,
    as a reward term (the paper states it as a constraint; the value is ours)."""

    def __post_init__(self) -> None:
        check_finite(self)
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            require(math.isfinite(value), f.name, value, "a finite number")


@dataclass(frozen=True)
class RewardConfig:
    """The reward: signed term weights apart from the thresholds the terms use."""

    weights: RewardWeights = field(default_factory=RewardWeights)
    fairness_min_deliveries: int = 3
    """The fairness term applies once more than this many deliveries happened."""
    stall_distance_m: float = 5.0
    """A slot with less displacement than this (and not docked) counts as a stall."""
    margin_epsilon_j: float = 1e-6
    """Regularises the relative energy margin (stored - need) / (need + epsilon)."""
    collision_sigma_m: float = 20.0
    safety_distance_m: float = 100.0
    """d_th."""
    deadline_speed_mps: float = 2.0
    """v_ref of the deadline shaping: the speed at which the dock is still reachable in time."""
    fairness_lambda: float = 1.0
    """lambda_f of the objective P1 (not a reward weight; used for the reported objective)."""

    def __post_init__(self) -> None:
        check_finite(self)
        for f in dataclasses.fields(self):
            if f.name != "weights":
                value = getattr(self, f.name)
                require(math.isfinite(value) and value >= 0, f.name, value, "a finite number >= 0")
        positive(self, "collision_sigma_m", "margin_epsilon_j")


@dataclass(frozen=True)
class PhysicsConfig:
    """MuJoCo model settings of the physics backend."""

    timestep_s: float = 0.05
    """Chosen by `iout-mj validate-energy` timestep convergence (see README)."""
    current_mps: Point = (0.0, 0.0)
    """Uniform ocean current (MuJoCo `wind`), world frame."""
    current_jitter_mps: float = 0.0
    """Per-episode random current of up to this speed, drawn from the task RNG."""

    def __post_init__(self) -> None:
        check_finite(self)
        require(0 < self.timestep_s <= 0.5, "timestep_s", self.timestep_s, "a number in (0, 0.5]")
        require(
            self.current_jitter_mps >= 0,
            "current_jitter_mps",
            self.current_jitter_mps,
            "a number >= 0",
        )


@dataclass(frozen=True)
class ScenarioConfig:
    """Geometry and horizon of a mission."""

    area_m: Point = (1000.0, 1000.0)
    nodes_m: tuple[Point, ...] = PAPER_LAYOUTS[7]
    n_auvs: int = 2
    starts_m: tuple[Point, ...] = DEFAULT_STARTS
    """Start positions; AUV i starts at starts_m[i]."""
    start_heading_rad: float = 0.0
    dock_center_m: Point = (830.0, 830.0)
    dock_radius_m: float = 70.0
    slot_s: float = 25.0
    horizon_slots: int = 55
    start_jitter_m: float = 10.0
    """Uniform random start offset of up to this many metres per axis (task RNG)."""
    start_heading_jitter_deg: float = 5.0

    def __post_init__(self) -> None:
        check_finite(self)
        ax, ay = self.area_m
        require(ax > 0 and ay > 0, "area_m", self.area_m, "two sides > 0 m")
        require(
            1 <= self.n_auvs <= MAX_AUVS, "n_auvs", self.n_auvs, f"an integer from 1 to {MAX_AUVS}"
        )
        k = len(self.nodes_m)
        require(
            MIN_NODES <= k <= MAX_NODES,
            "nodes_m",
            f"{k} nodes",
            f"{MIN_NODES} to {MAX_NODES} nodes",
        )
        for i, (x, y) in enumerate(self.nodes_m):
            require(0 <= x <= ax and 0 <= y <= ay, f"nodes_m[{i}]", (x, y), "a point inside area_m")
        require(
            len(self.starts_m) >= self.n_auvs,
            "starts_m",
            self.starts_m,
            f"at least n_auvs={self.n_auvs} points",
        )
        for i, (x, y) in enumerate(self.starts_m[: self.n_auvs]):
            require(
                0 < x < ax and 0 < y < ay,
                f"starts_m[{i}]",
                (x, y),
                "a point strictly inside area_m",
            )
        dx, dy = self.dock_center_m
        r = self.dock_radius_m
        require(r > 0, "dock_radius_m", r, "a radius > 0 m")
        require(
            r <= dx <= ax - r and r <= dy <= ay - r,
            "dock_center_m",
            self.dock_center_m,
            "a centre whose dock circle lies inside area_m",
        )
        positive(self, "slot_s")
        require(self.horizon_slots >= 1, "horizon_slots", self.horizon_slots, "an integer >= 1")
        require(self.start_jitter_m >= 0, "start_jitter_m", self.start_jitter_m, "a number >= 0")
        require(
            self.start_heading_jitter_deg >= 0,
            "start_heading_jitter_deg",
            self.start_heading_jitter_deg,
            "a number >= 0",
        )

    @property
    def n_nodes(self) -> int:
        return len(self.nodes_m)


@dataclass(frozen=True)
class Config:
    """Everything a mission needs; each part has the paper's defaults."""

    scenario: ScenarioConfig = field(default_factory=ScenarioConfig)
    motion: MotionConfig = field(default_factory=MotionConfig)
    acoustics: AcousticsConfig = field(default_factory=AcousticsConfig)
    network: NetworkConfig = field(default_factory=NetworkConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)
    physics: PhysicsConfig = field(default_factory=PhysicsConfig)

    def replace(self, **sections: Any) -> Config:
        """A copy with some sections replaced, e.g. `cfg.replace(scenario=...)`."""
        return dataclasses.replace(self, **sections)

    def to_dict(self) -> dict[str, Any]:
        return to_plain(self)

    def save(self, path: str | Path) -> None:
        """Write YAML (.yaml/.yml) or JSON (.json)."""
        path = Path(path)
        data = self.to_dict()
        if path.suffix == ".json":
            path.write_text(json.dumps(data, indent=2) + "\n")
        elif path.suffix in (".yaml", ".yml"):
            path.write_text(yaml.safe_dump(data, sort_keys=False))
        else:
            raise ConfigError(f"config file {path}: accepted suffixes .yaml, .yml, .json")

    @classmethod
    def from_dict(cls, data: Any) -> Config:
        return build_dataclass(cls, data, "config")

    @classmethod
    def load(cls, path: str | Path) -> Config:
        """Read a YAML or JSON file written by `save` (or by hand; missing keys take defaults)."""
        return cls.from_dict(load_mapping(path, "config file"))
