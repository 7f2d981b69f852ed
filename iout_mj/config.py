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

from iout_mj import vehicles
from iout_mj.paper import DEFAULT_STARTS, PAPER_LAYOUTS, Point
from iout_mj.schema import (
    ConfigError,
    build_dataclass,
    check_finite,
    check_types,
    in_range,
    load_mapping,
    one_of,
    require,
    to_plain,
)

MAX_AUVS = 4
MIN_NODES, MAX_NODES = 2, 30
MAX_SPEED_MPS = 20.0
"""Vehicle speeds and currents: the MuJoCo hull is validated up to here (fast torpedoes)."""
MAX_AREA_M = 20_000.0
"""Side of the operating area: with absorption at MAX_FREQUENCY_KHZ over its diagonal the
uplink need stays below 1e190 J (float64 overflows at 1e308)."""
MAX_FREQUENCY_KHZ = 200.0
"""Acoustic frequencies: Thorp's absorption is 51 dB/km here (see MAX_AREA_M)."""
FREQUENCY_WHY = "higher, Thorp's absorption over the area's diagonal overflows the uplink energy"
MIN_TIMESTEP_S, MAX_TIMESTEP_S = 1e-3, 0.25
"""MuJoCo timestep: a longer Euler step overshoots the hull's 500 N/(m/s) speed servo."""
MAX_HORIZON_SLOTS = 10_000
"""The log holds every slot (about 200 bytes per slot and env for 4 AUVs)."""
MAX_WEIGHT = 1e6
"""Reward weights: every term (quantities up to ~1e10) and their sum stay far inside float32."""
MAX_SUBSTEPS_PER_SLOT = 10_000
"""MuJoCo substeps per slot: the stepper records each one (about 700 bytes per scene with 4
AUVs), so a slot of a 36-scene batch stays under 300 MB."""
MAX_DURATION_S = MAX_SUBSTEPS_PER_SLOT * MAX_TIMESTEP_S
"""Slot and charging/uplink periods (2500 s)."""
MAX_FLOW_STEP_M = 1.25
"""Water-relative travel of a hull in one physics timestep (fastest flow x timestep): the
fins' lift diverges when the flow moves the hull most of its length (3 m) per step (measured
with random manoeuvres: stable at 1.25 m, divergent at 2.5 m within 3 slots of 2500 s). For
another vehicle: scaled by its length (not measured)."""
MAX_DRAG_STEP_KG = 10.0
"""drag_factor x fastest flow x timestep, the drag's momentum change per unit speed in one
explicit step, as a mass: a small part of the 247 kg hull, or Euler overshoots (measured:
stable at 10 kg, divergent at 20 kg with a 40 m/s cross flow). For another vehicle: scaled
by its mass (not measured)."""
MAX_SPECTRAL_EFFICIENCY = 64.0
"""data_rate_bps / bandwidth_hz: 2^64 - 1 is an SNR of 193 dB, beyond any modem."""
MIN_DRAG_FACTOR_NSPM2 = 4.5
"""Half the paper's 9 N s^2/m^2: with less drag the fixed 150 N m yaw servo and the fins
carry the paper's torpedo (whose drag is calibrated to it) sideways faster than V_max allows
for (speed over ground up to 4.5 V_max). A vehicle with drag of its own has no such bound."""


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
        check_types(self)
        check_finite(self)
        in_range(
            self,
            "v_max_mps",
            0.5,
            MAX_SPEED_MPS,
            "slower, the hull's own yaw manoeuvres exceed the speed scale of the observation",
        )
        in_range(self, "drag_coefficient", 1e-3, 0.1, "skin friction to a blunt hull")
        in_range(self, "wetted_area_m2", 0.5, 30.0, "the 3 m hull has about 3 m^2")
        in_range(self, "water_density_kgpm3", 900.0, 1100.0, "liquid water")
        in_range(self, "prop_efficiency", 0.05, 1.0)
        in_range(self, "hotel_power_w", 0.0, 1e5)
        in_range(self, "dtheta_max_deg", 0.0, 180.0, low_open=True)
        in_range(self, "dv_max_mps", 0.0, MAX_SPEED_MPS, low_open=True)
        in_range(self, "battery_j", 0.0, 1e12, low_open=True)
        for name in ("heading_levels", "speed_levels"):
            value = getattr(self, name)
            require(
                3 <= value <= 101 and value % 2 == 1,
                name,
                value,
                "an odd integer from 3 to 101 (the middle level is 'no change'; the policy "
                "has one output per level)",
            )
        in_range(self, "initial_speed_mps", 0.0, self.v_max_mps, "up to v_max_mps")

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
        check_types(self)
        check_finite(self)
        for name in ("f_wet_khz", "f_data_khz"):
            in_range(self, name, 0.1, MAX_FREQUENCY_KHZ, FREQUENCY_WHY)
        in_range(self, "p_tx_w", 1e-3, 1e6)
        for name in ("eta_tx", "eta_harv"):
            in_range(self, name, 0.01, 1.0)
        for name in ("di_tx_db", "di_rx_db"):
            in_range(self, name, 0.0, 40.0, "dB over an omnidirectional transducer")
        in_range(self, "spreading_factor", 1.0, 2.0, "cylindrical to spherical spreading")
        in_range(self, "rvs_db", -250.0, -100.0, "dB re 1 V/uPa")
        in_range(self, "load_resistance_ohm", 0.1, 1e6)
        in_range(self, "n_hydrophones", 1, 1000)
        in_range(self, "bandwidth_hz", 1.0, 1e6)
        in_range(
            self,
            "data_rate_bps",
            1.0,
            MAX_SPECTRAL_EFFICIENCY * self.bandwidth_hz,
            f"at most {MAX_SPECTRAL_EFFICIENCY:g} bit/s per Hz of bandwidth_hz: the required "
            "SNR 2^(R/B) - 1 overflows at 1024",
        )
        for name in ("charging_s", "data_s"):
            in_range(self, name, 0.0, MAX_DURATION_S, low_open=True)
        require(
            self.noise_model in ("flat", "wenz"),
            "noise_model",
            self.noise_model,
            "'flat' or 'wenz'",
        )
        in_range(self, "noise_level_db", 0.0, 150.0, "dB re 1 uPa^2/Hz")
        in_range(self, "shipping_activity", 0.0, 1.0)
        in_range(self, "wind_speed_mps", 0.0, 100.0)


CHANNEL_FEATURES = ("depth", "propagation", "packets", "interference", "fading")
"""The acoustic channel's optional features (`ChannelConfig.features`)."""
MODULATIONS = ("bpsk", "bfsk")
"""The uplink's modulations with a closed-form BER in AWGN (`acoustics.bit_error_rate`)."""
FADING_MODELS = ("rayleigh", "rician")
ABSORPTION_MODELS = ("thorp", "francois-garrison")
"""Absorption of sound in sea water (`ChannelConfig.absorption`)."""
FRANCOIS_GARRISON_RANGE = "Francois and Garrison (1982)'s range of validity"
MAX_PACKETS_PER_SLOT = 1000
"""Packets of one data period: the compiled binomial draw sums (1 - p)^n, which stays above
float64's smallest normal (2e-308) for n up to 1000 at p <= 1/2."""
MACKENZIE_RANGE = "Mackenzie (1981)'s range of validity"


@dataclass(frozen=True)
class ChannelConfig:
    """The acoustic network layer on top of the paper's link budget (off by default: the
    paper's deterministic, two-dimensional channel). Formulas and sources in
    `world.acoustics` and `world.network`."""

    features: tuple[str, ...] = ()
    """Features turned on, any of 'depth' (slant ranges from the depths below), 'propagation'
    (the handshake's travel times shorten the data period), 'packets' (packet errors from the
    modulation's BER at the link's SINR), 'interference' (simultaneous uplinks add to each
    other's noise), 'fading' (small-scale fading and log-normal shadowing per link and slot);
    () is the paper's channel."""
    node_depth_m: float = 100.0
    """Seabed depth of every node without its own (`node_depths_m`). Default: the shallow
    shelf of the paper's coastal IoUT setting (ours; the paper is two-dimensional)."""
    auv_depth_m: float = 50.0
    """Operating depth of every AUV without its own (`auv_depths_m`; ours: mid-water over the
    default seabed)."""
    node_depths_m: tuple[float, ...] = ()
    """Seabed depth of each node, one per node of the layout (a nodes file's or nodes_m's z
    column fills it); () gives every node node_depth_m."""
    auv_depths_m: tuple[float, ...] = ()
    """Operating depth of each AUV, AUV i at auv_depths_m[i] (at least n_auvs values); ()
    gives every AUV auv_depth_m."""
    temperature_degc: float = 10.0
    """Water temperature for the sound speed (Mackenzie 1981): a temperate-shelf mean (ours)."""
    salinity_ppt: float = 35.0
    """Salinity for the sound speed (Mackenzie 1981): standard sea water (parts per thousand)."""
    handshake_legs: int = 3
    """One-way propagation legs of the handshake inside the data period: the AUV's poll to
    the node, the node's packets back, the AUV's block acknowledgement to the node (3)."""
    modulation: str = "bpsk"
    """The uplink's modulation, for the BER at Eb/N0 = SINR B / R: 'bpsk' (coherent,
    0.5 erfc(sqrt(Eb/N0))) or 'bfsk' (non-coherent, 0.5 exp(-Eb/2N0)); Proakis, Digital
    Communications, 5th ed., sections 4.3 and 4.5."""
    packet_bits: int = 1000
    """Bits per packet, header included (ours: a 125-byte frame)."""
    delivery_share: float = 0.0
    """Share of a data period's packets that must arrive for the update to count as a
    delivery (AoI, K_reset); at least one packet always (0: any packet carries the update)."""
    fading_model: str = "rayleigh"
    """Small-scale fading of the 'fading' feature: 'rayleigh' or 'rician' (with
    rician_k_db); unit mean power gain."""
    rician_k_db: float = 10.0
    """Rician K factor (direct over scattered power) of 'rician' fading."""
    shadowing_sigma_db: float = 0.0
    """Standard deviation of the log-normal shadowing of the 'fading' feature (0: none)."""
    absorption: str = "thorp"
    """Absorption of sound in the link budget (AET and uplink): 'thorp' (the paper's eq. 3,
    frequency only) or 'francois-garrison' (Francois and Garrison 1982, J. Acoust. Soc. Am.
    72(6):1879: boric acid, magnesium sulphate and pure water at temperature_degc,
    salinity_ppt, ph and the mean depth). Applies whatever `features` are on."""
    ph: float = 8.0
    """Sea water pH for 'francois-garrison' absorption (its boric acid term)."""
    transmission_loss_file: str | None = None
    """A site-specific transmission-loss table (.npz, `iout-mj tl-table`; a relative path in a
    config file is taken from the file's folder): its TL at the horizontal range and the AUV's
    depth stands for spreading and absorption in every link budget (AET and uplink). Needs
    'depth' and 'thorp' absorption (the table holds its own); null: k_s 10 log10(d) + alpha d."""

    def __post_init__(self) -> None:
        check_types(self)
        check_finite(self)
        unknown = [f for f in self.features if f not in CHANNEL_FEATURES]
        require(
            not unknown and len(set(self.features)) == len(self.features),
            "features",
            self.features,
            "distinct names among " + ", ".join(repr(f) for f in CHANNEL_FEATURES),
        )
        for name in ("node_depth_m", "auv_depth_m"):
            in_range(self, name, 0.0, 8000.0, MACKENZIE_RANGE)
        for name in ("node_depths_m", "auv_depths_m"):
            depths = getattr(self, name)
            require(
                all(0.0 <= z <= 8000.0 for z in depths),
                name,
                depths,
                "depths in [0, 8000] m below the surface (positive down; " + MACKENZIE_RANGE + ")",
            )
        seabed_m = min(self.node_depths_m or (self.node_depth_m,))
        auv_m = max(self.auv_depths_m or (self.auv_depth_m,))
        require(
            auv_m <= seabed_m,
            "auv_depths_m" if self.auv_depths_m else "auv_depth_m",
            self.auv_depths_m or self.auv_depth_m,
            f"depths at most the shallowest node's seabed, {seabed_m:g} m (above the seabed)",
        )
        in_range(self, "temperature_degc", 2.0, 30.0, MACKENZIE_RANGE)
        in_range(self, "salinity_ppt", 25.0, 40.0, MACKENZIE_RANGE)
        in_range(self, "handshake_legs", 0, 10)
        one_of(self, "modulation", MODULATIONS)
        in_range(self, "packet_bits", 8, 10**7)
        in_range(self, "delivery_share", 0.0, 1.0)
        one_of(self, "fading_model", FADING_MODELS)
        in_range(self, "rician_k_db", -20.0, 40.0, "Rayleigh-like to nearly line of sight")
        in_range(self, "shadowing_sigma_db", 0.0, 20.0)
        one_of(self, "absorption", ABSORPTION_MODELS)
        in_range(self, "ph", 7.7, 8.3, FRANCOIS_GARRISON_RANGE)
        self._check_table_settings()
        if self.absorption == "francois-garrison":
            in_range(self, "temperature_degc", -2.0, 22.0, FRANCOIS_GARRISON_RANGE)
            in_range(self, "salinity_ppt", 30.0, 35.0, FRANCOIS_GARRISON_RANGE)
            require(
                self.mean_depth_m <= 3500.0,
                "node_depth_m",
                self.node_depths_m or self.node_depth_m,
                f"depths whose mean_depth_m is at most 3500 m ({FRANCOIS_GARRISON_RANGE})",
            )

    def _check_table_settings(self) -> None:
        """What a transmission-loss table needs of the channel (its contents are checked
        where a link budget loads it, `world.tl_table.link_values`)."""
        path = self.transmission_loss_file
        require(
            path is None or path.endswith(".npz"),
            "transmission_loss_file",
            path,
            "a path to an .npz table (`iout-mj tl-table`), or null",
        )
        require(
            path is None or self.on("depth"),
            "features",
            self.features,
            "'depth' among them with a transmission_loss_file (its TL is over the AUV's depth)",
        )
        require(
            path is None or self.absorption == "thorp",
            "absorption",
            self.absorption,
            "'thorp' with a transmission_loss_file (the table holds its own absorption)",
        )

    @property
    def mean_depth_m(self) -> float:
        """The water column's one depth for sound speed and absorption: the mean of the AUVs'
        mean depth and the nodes' mean depth."""
        auv = self.auv_depths_m or (self.auv_depth_m,)
        node = self.node_depths_m or (self.node_depth_m,)
        return 0.5 * (sum(auv) / len(auv) + sum(node) / len(node))

    def depths_m(self, n_auvs: int, n_nodes: int) -> tuple[list[float], list[float]]:
        """The (N,) AUV and (K,) node depths the rules use: every one 0 with 'depth' off (the
        paper's horizontal ranges)."""
        if not self.on("depth"):
            return [0.0] * n_auvs, [0.0] * n_nodes
        auv = list(self.auv_depths_m[:n_auvs]) or [self.auv_depth_m] * n_auvs
        return auv, list(self.node_depths_m) or [self.node_depth_m] * n_nodes

    def on(self, feature: str) -> bool:
        """Whether `feature` (one of CHANNEL_FEATURES) is turned on."""
        return feature in self.features

    @property
    def label(self) -> str:
        """The channel in one word for result rows and figures: "paper" (no feature, Thorp),
        else its features, a non-Thorp absorption and "tl-table" (with a transmission-loss
        table) joined by '+' ("depth+packets", ...)."""
        extra = () if self.absorption == "thorp" else (self.absorption,)
        table = () if self.transmission_loss_file is None else ("tl-table",)
        return "+".join((*self.features, *extra, *table)) or PAPER_CHANNEL


PAPER_CHANNEL = "paper"
"""`ChannelConfig.label` of the paper's deterministic channel."""


@dataclass(frozen=True)
class NetworkConfig:
    """Sensor-node state rules (paper section III-A; open values from the authors' code)."""

    k_reset: int = 3
    aoi_max: float = 50.0
    node_initial_energy_j: float = 0.1

    def __post_init__(self) -> None:
        check_types(self)
        check_finite(self)
        in_range(self, "k_reset", 1, MAX_HORIZON_SLOTS, "deliveries per AoI reset")
        in_range(self, "aoi_max", 1.0, 1e6, "slots")
        in_range(self, "node_initial_energy_j", 0.0, 1e9)


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
        check_types(self)
        check_finite(self)
        for f in dataclasses.fields(self):
            in_range(self, f.name, -MAX_WEIGHT, MAX_WEIGHT)


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
        check_types(self)
        check_finite(self)
        in_range(self, "fairness_min_deliveries", 0, 1_000_000)
        for name in ("stall_distance_m", "safety_distance_m"):
            in_range(self, name, 0.0, MAX_AREA_M)
        in_range(self, "margin_epsilon_j", 1e-12, 1e6)
        in_range(
            self,
            "collision_sigma_m",
            0.1,
            MAX_AREA_M,
            "the Gaussian divides by sigma^2, which must not underflow",
        )
        in_range(self, "deadline_speed_mps", 0.0, MAX_SPEED_MPS)
        in_range(self, "fairness_lambda", 0.0, MAX_WEIGHT)


@dataclass(frozen=True)
class PhysicsConfig:
    """MuJoCo model settings of the physics backend."""

    timestep_s: float = 0.05
    """Chosen by `iout-mj validate-energy` timestep convergence (see README)."""
    current_mps: Point = (0.0, 0.0)
    """Uniform ocean current (MuJoCo `wind`), world frame."""
    current_jitter_mps: float = 0.0
    """Per-episode random current of up to this speed, drawn from the task RNG."""
    vehicle: str = vehicles.DEFAULT
    """The MuJoCo hull (`iout_mj.vehicles`): 'paper-torpedo' (3 m, drag calibrated to the
    paper's C_d S) or 'remus100' (Prestero 2001). In a config file it also sets the motion
    values the vehicle implies (V_max, rho, C_d, S) that the file does not set itself."""

    def __post_init__(self) -> None:
        check_types(self)
        check_finite(self)
        one_of(self, "vehicle", sorted(vehicles.VEHICLES))
        in_range(
            self,
            "timestep_s",
            MIN_TIMESTEP_S,
            MAX_TIMESTEP_S,
            "a longer Euler step overshoots the hull's 500 N/(m/s) speed servo",
        )
        require(
            all(abs(c) <= MAX_SPEED_MPS for c in self.current_mps),
            "current_mps",
            self.current_mps,
            f"components in [-{MAX_SPEED_MPS:g}, {MAX_SPEED_MPS:g}] m/s",
        )
        in_range(
            self,
            "current_jitter_mps",
            0.0,
            MAX_SPEED_MPS / math.sqrt(2.0),
            "per axis; the vehicle must out-run it",
        )

    @property
    def max_current_mps(self) -> float:
        """The fastest current of any episode: the jitter is drawn per axis."""
        return math.hypot(*self.current_mps) + math.sqrt(2.0) * self.current_jitter_mps


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
    dock_max_speed_mps: float | None = None
    """An AUV docks when it ends a slot inside the dock zone at or below this speed through
    the water; null: on entering the zone at any speed (the paper's rule), so a tour through
    the zone ends that AUV's mission."""
    slot_s: float = 25.0
    horizon_slots: int = 55
    start_jitter_m: float = 10.0
    """Uniform random start offset of up to this many metres per axis (task RNG)."""
    start_heading_jitter_deg: float = 5.0

    def __post_init__(self) -> None:
        check_types(self)
        check_finite(self)
        ax, ay = self.area_m
        require(
            10 <= ax <= MAX_AREA_M and 10 <= ay <= MAX_AREA_M,
            "area_m",
            self.area_m,
            f"two sides from 10 to {MAX_AREA_M:g} m",
        )
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
        v = self.dock_max_speed_mps
        require(v is None or v > 0, "dock_max_speed_mps", v, "a speed > 0 m/s, or null")
        require(
            r <= dx <= ax - r and r <= dy <= ay - r,
            "dock_center_m",
            self.dock_center_m,
            "a centre whose dock circle lies inside area_m",
        )
        in_range(self, "start_heading_rad", -2 * math.pi, 2 * math.pi, "one turn either way")
        in_range(self, "slot_s", 0.1, MAX_DURATION_S)
        in_range(self, "horizon_slots", 1, MAX_HORIZON_SLOTS, "the log holds every slot")
        in_range(self, "start_jitter_m", 0.0, MAX_AREA_M)
        in_range(self, "start_heading_jitter_deg", 0.0, 180.0)

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
    channel: ChannelConfig = field(default_factory=ChannelConfig)

    def __post_init__(self) -> None:
        """Bounds that join sections (each section checked its own when built)."""
        check_types(self)
        slot_s, m, ph = self.scenario.slot_s, self.motion, self.physics
        self._check_channel()
        for name in ("charging_s", "data_s"):
            value = getattr(self.acoustics, name)
            require(
                value <= slot_s,
                f"acoustics.{name}",
                value,
                f"at most one slot (scenario.slot_s={slot_s:g} s)",
            )
        require(
            ph.max_current_mps <= m.v_max_mps,
            "physics.current_mps",
            ph.current_mps,
            f"a current the vehicle can out-run: |current_mps| + sqrt(2) current_jitter_mps = "
            f"{ph.max_current_mps:.3g} m/s at most motion.v_max_mps={m.v_max_mps:g} (then the "
            "speed over ground stays within 2 V_max, the top of its observation)",
        )
        substeps = round(slot_s / ph.timestep_s)
        require(
            abs(substeps * ph.timestep_s - slot_s) <= 1e-9 * slot_s
            and substeps <= MAX_SUBSTEPS_PER_SLOT,
            "physics.timestep_s",
            ph.timestep_s,
            f"a divisor of scenario.slot_s={slot_s:g} s into at most {MAX_SUBSTEPS_PER_SLOT} "
            "substeps (MuJoCo records every substep of a slot)",
        )
        hull = vehicles.get(ph.vehicle)
        if hull.hull_drag_nspm2 is None:  # the hull's drag is the config's
            require(
                m.drag_factor_nspm2 >= MIN_DRAG_FACTOR_NSPM2,
                "motion.drag_coefficient",
                m.drag_coefficient,
                f"rho*C_d*S/2 >= {MIN_DRAG_FACTOR_NSPM2} N s^2/m^2 (here "
                f"{m.drag_factor_nspm2:.3g}: less drag lets the hull's own yaw manoeuvres "
                "carry it faster than V_max)",
            )
        flow_mps = m.v_max_mps + ph.max_current_mps
        max_flow_step_m = MAX_FLOW_STEP_M * hull.length_m / vehicles.PAPER_TORPEDO.length_m
        require(
            flow_mps * ph.timestep_s <= max_flow_step_m,
            "physics.timestep_s",
            ph.timestep_s,
            f"at most {max_flow_step_m / flow_mps:.3g} s: the water passes the hull at up to "
            f"v_max + current = {flow_mps:.3g} m/s, and more than {max_flow_step_m:.3g} m per "
            "step diverges",
        )
        drag = vehicles.hull_drag_nspm2(ph.vehicle, m.drag_factor_nspm2)
        max_drag_kg = MAX_DRAG_STEP_KG * hull.mass_kg / vehicles.PAPER_TORPEDO.mass_kg
        require(
            drag * flow_mps * ph.timestep_s <= max_drag_kg,
            "physics.timestep_s",
            ph.timestep_s,
            f"at most {max_drag_kg / (drag * flow_mps):.3g} s with the hull's drag "
            f"{drag:.3g} N s^2/m^2 and flow up to {flow_mps:.3g} m/s (drag x flow x timestep "
            f"must be at most {max_drag_kg:.3g} kg, or the explicit step overshoots)",
        )

    def _check_channel(self) -> None:
        """The channel's bounds that involve the acoustics and scenario sections."""
        ch, ac, sc = self.channel, self.acoustics, self.scenario
        if ch.node_depths_m:
            require(
                len(ch.node_depths_m) == sc.n_nodes,
                "channel.node_depths_m",
                f"{len(ch.node_depths_m)} depths",
                f"one depth per node of scenario.nodes_m ({sc.n_nodes}), or none",
            )
        if ch.auv_depths_m:
            require(
                len(ch.auv_depths_m) >= sc.n_auvs,
                "channel.auv_depths_m",
                f"{len(ch.auv_depths_m)} depths",
                f"at least one depth per AUV (scenario.n_auvs={sc.n_auvs}), or none",
            )
        if ch.on("packets"):
            packets = math.floor(ac.data_rate_bps * ac.data_s / ch.packet_bits)
            require(
                1 <= packets <= MAX_PACKETS_PER_SLOT,
                "channel.packet_bits",
                ch.packet_bits,
                f"a size that fits 1 to {MAX_PACKETS_PER_SLOT} packets into one data period "
                f"(acoustics.data_rate_bps x data_s = {ac.data_rate_bps * ac.data_s:g} bits)",
            )
        if ch.on("interference"):
            gap_hz = abs(ac.f_wet_khz - ac.f_data_khz) * 1000.0
            require(
                gap_hz > ac.bandwidth_hz / 2,
                "acoustics.f_wet_khz",
                ac.f_wet_khz,
                "an AET frequency outside the data band f_data_khz +- bandwidth_hz / 2 with "
                "channel interference on (the model leaves the AET tone out of the uplinks' "
                "noise, which holds only out of band)",
            )

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

    def with_vehicle(self, name: str) -> Config:
        """A copy flying vehicle `name`, with the motion values that vehicle implies."""
        vehicles.get(name)
        return self.replace(
            physics=dataclasses.replace(self.physics, vehicle=name),
            motion=dataclasses.replace(self.motion, **vehicles.get(name).motion),
        )

    @classmethod
    def from_dict(cls, data: Any, name: str = "config") -> Config:
        """A config from plain data (`name`: where it stands, for messages); `physics.vehicle`
        fills the motion values the vehicle implies that `data` does not set. Every config
        read as a section of another (a training config's `env:`) is built here too."""
        physics = data.get("physics") if isinstance(data, dict) else None
        vehicle = physics.get("vehicle") if isinstance(physics, dict) else None
        if isinstance(vehicle, str) and vehicle in vehicles.VEHICLES:
            motion = data.get("motion", {})
            if isinstance(motion, dict):
                data = {**data, "motion": {**vehicles.get(vehicle).motion, **motion}}
        return build_dataclass(cls, _node_depths_apart(data), name)

    @classmethod
    def load(cls, path: str | Path) -> Config:
        """Read a YAML or JSON file written by `save` (or by hand; missing keys take defaults);
        relative file paths in it are taken from its folder (`files_from_folder`)."""
        return cls.from_dict(
            files_from_folder(load_mapping(path, "config file"), Path(path).parent)
        )


def files_from_folder(data: Any, folder: Path) -> Any:
    """Plain config data whose relative channel.transmission_loss_file is joined to `folder`
    (the config file's) and made absolute, so that a run's saved config reads the same file
    from its own folder; other data as it is."""
    channel: Any = data.get("channel") if isinstance(data, dict) else None
    path = channel.get("transmission_loss_file") if isinstance(channel, dict) else None
    if not isinstance(path, str) or Path(path).is_absolute():
        return data
    absolute = str((folder / path).resolve())
    return {**data, "channel": {**channel, "transmission_loss_file": absolute}}


def _node_depths_apart(data: Any) -> Any:
    """Plain config data whose scenario.nodes_m rows carry a seabed depth (x, y, z) as the
    same nodes (x, y) and channel.node_depths_m (z); other data as it is."""
    scenario: Any = data.get("scenario") if isinstance(data, dict) else None
    nodes = scenario.get("nodes_m") if isinstance(scenario, dict) else None
    if not isinstance(nodes, list) or not any(
        isinstance(row, (list, tuple)) and len(row) == 3 for row in nodes
    ):
        return data
    channel = data.get("channel", {})
    require(
        all(isinstance(row, (list, tuple)) and len(row) == 3 for row in nodes)
        and isinstance(channel, dict)
        and "node_depths_m" not in channel,
        "scenario.nodes_m",
        nodes,
        "every row (x, y) or every row (x, y, z) with z the seabed depth (then without "
        "channel.node_depths_m)",
    )
    depths = {"node_depths_m": [row[2] for row in nodes]}
    return {
        **data,
        "scenario": {**scenario, "nodes_m": [list(row[:2]) for row in nodes]},
        "channel": {**channel, **depths} if isinstance(channel, dict) else depths,
    }
