"""Acoustic link budget: Thorp absorption, sonar equation, AET harvest and uplink energy (numpy).

The combination implemented (DESIGN.md section 4; the paper's symbols):

- alpha(f) [dB/km], f in kHz: Thorp (paper eq. 3), or Francois and Garrison (1982) with a
  channel's `absorption` (`absorption_db_per_km`).
- TL(d) = k_s * 10 log10(max(d, 1 m)) + alpha(f) * d / 1000.
- SL = 170.8 + 10 log10(P_elec) + 10 log10(eta_tx) + DI_tx.
- AET: RL = SL - TL + DI_rx and P_harv = eta_harv * n_hyd * 10^((RL + RVS)/10) / (4 R_p).
  The paper writes RL = SL - AL - NL; ambient noise does not reduce the acoustic power a
  harvester collects, so the noise term is used for the uplink only.
- Uplink: gamma_req = 10 log10(2^(R/B) - 1); NL_band = NL(f_data) + 10 log10(B);
  SL_req = gamma_req + TL + NL_band; P_trans = 10^((SL_req - 170.8 - 10 log10 eta_tx - DI_tx)/10).

All functions take scalars or arrays of distances (any shape, e.g. AUVs x nodes).

The acoustic network layer (`config.ChannelConfig`, off by default) adds, in the compiled
rules (`world/network.c`), with the constants of `ChannelConstants`: slant ranges from the
depths; the sound speed of Mackenzie (1981) and the handshake's travel times; packets whose
error rate follows the modulation's BER at the link's SINR; interference between the uplinks
of a slot; Rician/Rayleigh fading and log-normal shadowing. `world.network` states the rules.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from iout_mj import native
from iout_mj.config import AcousticsConfig, ChannelConfig
from iout_mj.types import FloatArray
from iout_mj.world import tl_table  # a module: tl_table uses this one's functions

SL_REF_DB = 170.8
"""Source level of 1 W of acoustic power radiated omnidirectionally, dB re 1 uPa at 1 m."""
MIN_DISTANCE_M = 1.0
"""Transmission loss is referred to 1 m; closer distances count as 1 m."""


def thorp_absorption_db_per_km(f_khz: ArrayLike) -> FloatArray:
    """Thorp's absorption coefficient alpha(f) in dB/km for f in kHz."""
    f2 = np.square(np.asarray(f_khz, dtype=float))
    return 0.11 * f2 / (1 + f2) + 44 * f2 / (4100 + f2) + 2.75e-4 * f2 + 0.003


def francois_garrison_absorption_db_per_km(
    f_khz: ArrayLike,
    temperature_degc: float,
    salinity_ppt: float,
    depth_m: float,
    ph: float = 8.0,
) -> FloatArray:
    """Francois and Garrison (1982)'s absorption coefficient in dB/km for f in kHz (J. Acoust.
    Soc. Am. 72(6):1879-1890, eqs. 2-4), by the compiled `iout_francois_garrison`:

    alpha = A1 P1 f1 f^2 / (f1^2 + f^2)     boric acid, A1 = 8.86 / c 10^(0.78 pH - 5),
                                            f1 = 2.8 sqrt(S / 35) 10^(4 - 1245 / theta)
          + A2 P2 f2 f^2 / (f2^2 + f^2)     MgSO4, A2 = 21.44 S / c (1 + 0.025 T),
                                            P2 = 1 - 1.37e-4 z + 6.2e-9 z^2,
                                            f2 = 8.17 10^(8 - 1990 / theta) / (1 + 0.0018 (S - 35))
          + A3 P3 f^2                       pure water, A3 a cubic in T (two branches at
                                            20 C), P3 = 1 - 3.83e-5 z + 4.9e-10 z^2

    with c = 1412 + 3.21 T + 1.19 S + 0.0167 z and theta = 273 + T (T in C, S in ppt, z in m).
    """
    shape = np.shape(f_khz)
    f = np.ascontiguousarray(np.reshape(np.asarray(f_khz, dtype=float), -1))
    alpha = np.empty_like(f)
    native.call(
        native.lib.iout_francois_garrison,
        native.address(f),
        f.size,
        float(temperature_degc),
        float(salinity_ppt),
        float(depth_m),
        float(ph),
        native.address(alpha),
    )
    return alpha.reshape(shape)


def absorption_db_per_km(f_khz: ArrayLike, channel: ChannelConfig | None = None) -> FloatArray:
    """The absorption coefficient the link budget uses: Thorp's (no channel, or
    `channel.absorption` 'thorp') or Francois and Garrison's at the channel's water (its
    temperature, salinity, pH and mean depth)."""
    if channel is None or channel.absorption == "thorp":
        return thorp_absorption_db_per_km(f_khz)
    return francois_garrison_absorption_db_per_km(
        f_khz, channel.temperature_degc, channel.salinity_ppt, channel.mean_depth_m, channel.ph
    )


def transmission_loss_db(
    distance_m: ArrayLike,
    f_khz: float,
    spreading_factor: float,
    channel: ChannelConfig | None = None,
) -> FloatArray:
    """TL = k_s * 10 log10(d) + alpha(f) d/1000, with d in metres (at least 1 m) and alpha of
    `absorption_db_per_km` (Thorp without a channel)."""
    d = np.maximum(np.asarray(distance_m, dtype=float), MIN_DISTANCE_M)
    return spreading_factor * 10 * np.log10(d) + absorption_db_per_km(f_khz, channel) * d / 1000


def source_level_db(p_elec_w: ArrayLike, eta: float, di_db: float) -> FloatArray:
    """SL = 170.8 + 10 log10(P_elec) + 10 log10(eta) + DI, dB re 1 uPa at 1 m."""
    return SL_REF_DB + 10 * np.log10(np.asarray(p_elec_w, dtype=float)) + 10 * np.log10(eta) + di_db


def noise_psd_db(f_khz: ArrayLike, cfg: AcousticsConfig) -> FloatArray:
    """Ambient noise spectral level in dB re 1 uPa^2/Hz.

    'flat' returns `cfg.noise_level_db`. 'wenz' sums the four empirical components
    (turbulence, shipping, wind, thermal) in the form of Stojanovic (2007), with shipping
    activity s in [0, 1] and wind speed w in m/s.
    """
    f = np.asarray(f_khz, dtype=float)
    if cfg.noise_model == "flat":
        return np.full_like(f, cfg.noise_level_db)
    s, w = cfg.shipping_activity, cfg.wind_speed_mps
    lf = np.log10(f)
    turbulence = 17 - 30 * lf
    shipping = 40 + 20 * (s - 0.5) + 26 * lf - 60 * np.log10(f + 0.03)
    wind = 50 + 7.5 * np.sqrt(w) + 20 * lf - 40 * np.log10(f + 0.4)
    thermal = -15 + 20 * lf
    components = np.stack([turbulence, shipping, wind, thermal])
    return 10 * np.log10(np.sum(10 ** (components / 10), axis=0))


def harvest_power_w(
    distance_m: ArrayLike, cfg: AcousticsConfig, channel: ChannelConfig | None = None
) -> FloatArray:
    """Electrical power harvested by a node at `distance_m` from the AET projector (the
    channel's absorption model; Thorp without one)."""
    sl = source_level_db(cfg.p_tx_w, cfg.eta_tx, cfg.di_tx_db)
    tl = transmission_loss_db(distance_m, cfg.f_wet_khz, cfg.spreading_factor, channel)
    rl = sl - tl + cfg.di_rx_db
    return (
        cfg.eta_harv
        * cfg.n_hydrophones
        * 10 ** ((rl + cfg.rvs_db) / 10)
        / (4 * cfg.load_resistance_ohm)
    )


def required_snr_db(cfg: AcousticsConfig) -> float:
    """Shannon-bound SNR for rate R over bandwidth B: 10 log10(2^(R/B) - 1)."""
    return float(10 * np.log10(2 ** (cfg.data_rate_bps / cfg.bandwidth_hz) - 1))


def uplink_power_w(
    distance_m: ArrayLike, cfg: AcousticsConfig, channel: ChannelConfig | None = None
) -> FloatArray:
    """Electrical transmit power a node needs to reach an AUV at `distance_m` at rate R."""
    nl_band = noise_psd_db(cfg.f_data_khz, cfg) + 10 * np.log10(cfg.bandwidth_hz)
    tl = transmission_loss_db(distance_m, cfg.f_data_khz, cfg.spreading_factor, channel)
    sl_req = required_snr_db(cfg) + tl + nl_band
    return 10 ** ((sl_req - SL_REF_DB - 10 * np.log10(cfg.eta_tx) - cfg.di_tx_db) / 10)


def harvest_energy_j(
    distance_m: ArrayLike, cfg: AcousticsConfig, channel: ChannelConfig | None = None
) -> FloatArray:
    """Energy harvested over one charging period tau_charging."""
    return harvest_power_w(distance_m, cfg, channel) * cfg.charging_s


def uplink_energy_j(
    distance_m: ArrayLike, cfg: AcousticsConfig, channel: ChannelConfig | None = None
) -> FloatArray:
    """Energy E_req a node spends to deliver one update over tau_data."""
    return uplink_power_w(distance_m, cfg, channel) * cfg.data_s


LINK_DTYPE = native.record_dtype("Link")
"""The link budget's distance-independent constants (`LinkBudget`), as the compiled rules
read them (native.h's IOUT_LINK)."""


class LinkBudget(native.Frozen):
    """The same link budget with every distance-independent term folded into a constant, for
    the per-slot hot path: per distance, one power and two exponentials.

    harvest(d) = c_h d^-k_s 10^(-alpha_wet d / 10^4)
    uplink(d) = c_u d^k_s 10^(alpha_data d / 10^4)

    with alpha of the channel's absorption model (Thorp without a channel). With the channel's
    transmission_loss_file (`world.tl_table`), harvest = c_h 10^(-TL_wet / 10) and uplink =
    c_u 10^(TL_data / 10), the table's TL interpolated at the horizontal range and the AUV's
    depth (the compiled `iout_link_energy`, which every link budget of the rules calls).
    """

    def __init__(self, cfg: AcousticsConfig, channel: ChannelConfig | None = None):
        sl = source_level_db(cfg.p_tx_w, cfg.eta_tx, cfg.di_tx_db)
        c_harvest_j = (
            cfg.eta_harv
            * cfg.n_hydrophones
            * cfg.charging_s
            * 10 ** ((sl + cfg.di_rx_db + cfg.rvs_db) / 10)
            / (4 * cfg.load_resistance_ohm)
        )
        nl_band = float(noise_psd_db(cfg.f_data_khz, cfg)) + 10 * np.log10(cfg.bandwidth_hz)
        c_uplink_j = cfg.data_s * 10 ** (
            (required_snr_db(cfg) + nl_band - SL_REF_DB - 10 * np.log10(cfg.eta_tx) - cfg.di_tx_db)
            / 10
        )
        ln10 = np.log(10.0)
        values = {
            "harvest_j": c_harvest_j,
            "uplink_j": c_uplink_j,
            "wet_per_m": -float(absorption_db_per_km(cfg.f_wet_khz, channel)) * ln10 / 1e4,
            "data_per_m": float(absorption_db_per_km(cfg.f_data_khz, channel)) * ln10 / 1e4,
            "spreading": cfg.spreading_factor,
            "min_distance_m": MIN_DISTANCE_M,
            "bits_per_delivery": bits_per_delivery(cfg),
            **tl_table.link_values(cfg, channel),
        }
        native.require_names("Link", tuple(sorted(LINK_DTYPE.names or ())), tuple(sorted(values)))
        constants = native.allocate((1,), LINK_DTYPE)
        for name, value in values.items():
            constants[name] = value
        self.constants = native.read_only(constants)
        """(1,) record of LINK_DTYPE (read-only: the compiled rules read it)."""
        self._freeze()

    @property
    def has_table(self) -> bool:
        """Whether a transmission-loss table stands for spreading and absorption."""
        return bool(self.constants["tl_ranges"][0])

    def energies_j(
        self, horizontal_m: ArrayLike, auv_depth_m: ArrayLike = 0.0, node_depth_m: ArrayLike = 0.0
    ) -> tuple[FloatArray, FloatArray]:
        """(harvested energy per slot, uplink energy E_req) of links at horizontal ranges,
        AUV depths and node depths (broadcast together; the slant range with the formula, the
        range and the AUV's depth with a table), by the compiled link budget, the
        function the slot rules use (`iout_link_pair_energies`)."""
        shape = np.broadcast_shapes(
            *(np.shape(x) for x in (horizontal_m, auv_depth_m, node_depth_m))
        )
        h, a, z = (
            np.ascontiguousarray(x, dtype=float)
            for x in np.broadcast_arrays(
                np.asarray(horizontal_m, float),
                np.asarray(auv_depth_m, float),
                np.asarray(node_depth_m, float),
            )
        )
        harvest, uplink = np.empty_like(h), np.empty_like(h)
        native.call(
            native.lib.iout_link_pair_energies,
            native.address(self.constants),
            native.address(h),
            native.address(a),
            native.address(z),
            h.size,
            native.address(harvest),
            native.address(uplink),
        )
        return harvest.reshape(shape), uplink.reshape(shape)

    def transmission_loss_db(
        self, horizontal_m: ArrayLike, auv_depth_m: ArrayLike = 0.0, node_depth_m: ArrayLike = 0.0
    ) -> tuple[FloatArray, FloatArray]:
        """The TL (dB) at the AET and at the data frequency that `energies_j` applies: the
        table's, or k_s 10 log10(d) + alpha d / 1000."""
        harvest, uplink = self.energies_j(horizontal_m, auv_depth_m, node_depth_m)
        c = self.constants[0]
        return -10 * np.log10(harvest / c["harvest_j"]), 10 * np.log10(uplink / c["uplink_j"])


def bits_per_delivery(cfg: AcousticsConfig) -> float:
    """Data delivered by one successful uplink: R * tau_data."""
    return cfg.data_rate_bps * cfg.data_s


def mackenzie_sound_speed_mps(
    temperature_degc: ArrayLike, salinity_ppt: ArrayLike, depth_m: ArrayLike
) -> FloatArray:
    """Sound speed in sea water, Mackenzie's nine-term equation (Mackenzie 1981, J. Acoust.
    Soc. Am. 70(3):807-812; valid for T 2-30 C, S 25-40 ppt, z 0-8000 m, standard error
    0.07 m/s; his check value: 1550.744 m/s at 25 C, 35 ppt, 1000 m):

    c = 1448.96 + 4.591 T - 5.304e-2 T^2 + 2.374e-4 T^3 + 1.340 (S - 35) + 1.630e-2 z
        + 1.675e-7 z^2 - 1.025e-2 T (S - 35) - 7.139e-13 T z^3
    """
    t = np.asarray(temperature_degc, dtype=float)
    ds = np.asarray(salinity_ppt, dtype=float) - 35.0
    z = np.asarray(depth_m, dtype=float)
    return np.asarray(
        1448.96
        + 4.591 * t
        - 5.304e-2 * t**2
        + 2.374e-4 * t**3
        + 1.340 * ds
        + 1.630e-2 * z
        + 1.675e-7 * z**2
        - 1.025e-2 * t * ds
        - 7.139e-13 * t * z**3
    )


def sound_speed_mps(cfg: ChannelConfig) -> float:
    """The channel's sound speed: Mackenzie's at the mean of the AUV and node depths (one
    value per config: the handshake's legs are short against the water column's structure)."""
    return float(
        mackenzie_sound_speed_mps(cfg.temperature_degc, cfg.salinity_ppt, cfg.mean_depth_m)
    )


CHANNEL_DTYPE = native.record_dtype("Channel")
"""The channel's constants as the compiled rules read them (native.h's IOUT_CHANNEL)."""
MODULATION_CODES = {"bpsk": 0, "bfsk": 1}
"""native.h's IOUT_BPSK and IOUT_BFSK."""


def channel_values(channel: ChannelConfig, cfg: AcousticsConfig) -> dict[str, float]:
    """The Channel record's values of a config (every feature off: the paper's channel)."""
    on = channel.on
    snr_req = 2 ** (cfg.data_rate_bps / cfg.bandwidth_hz) - 1
    delay = channel.handshake_legs / sound_speed_mps(channel)
    return {
        "enabled": int(bool(channel.features)),
        "delay_s_per_m": delay if on("propagation") else 0.0,
        "data_s": cfg.data_s,
        "data_rate_bps": cfg.data_rate_bps,
        "packets": int(on("packets")),
        "packet_bits": float(channel.packet_bits),
        "delivery_share": channel.delivery_share,
        "modulation": MODULATION_CODES[channel.modulation],
        "ebn0_per_snr": cfg.bandwidth_hz / cfg.data_rate_bps,
        "snr_req": snr_req,
        "interference": int(on("interference")),
        "fading": int(on("fading")),
        "rician_k": 10 ** (channel.rician_k_db / 10) if channel.fading_model == "rician" else 0.0,
        "shadowing_sigma_db": channel.shadowing_sigma_db,
    }


class ChannelConstants(native.Frozen):
    """The channel's constants for the compiled rules (a read-only (1,) CHANNEL_DTYPE record)
    and whether a slot needs uniform draws (packets or fading on)."""

    def __init__(self, channel: ChannelConfig, cfg: AcousticsConfig):
        values = channel_values(channel, cfg)
        names = tuple(sorted(CHANNEL_DTYPE.names or ()))
        native.require_names("Channel", names, tuple(sorted(values)))
        record = native.allocate((1,), CHANNEL_DTYPE)
        for name, value in values.items():
            record[name] = value
        self.constants = native.read_only(record)
        self.enabled = bool(channel.features)
        self.draws = channel.on("packets") or channel.on("fading")
        """Whether each slot draws uniforms (`Mission.channel_draws`) from the task RNG."""
        self._freeze()

    def packet_error_rate(self, sinr_db: ArrayLike) -> FloatArray:
        """PER = 1 - (1 - BER)^bits at each SINR (dB), BER of the channel's modulation at
        Eb/N0 = SINR B / R, by the compiled rules' own function."""
        sinr = np.ascontiguousarray(10 ** (np.asarray(sinr_db, dtype=float) / 10))
        per = np.empty_like(sinr)
        native.call(
            native.lib.iout_packet_error_rates,
            native.address(self.constants),
            native.address(sinr),
            sinr.size,
            native.address(per),
        )
        return per


def channel_link_budget(
    channel: ChannelConfig,
    cfg: AcousticsConfig,
    horizontal_m: float,
    auv_depth_m: float,
    node_depth_m: float,
) -> dict[str, float]:
    """One uplink through the channel at a horizontal range and a pair of depths, alone in
    its slot and without fading (`world.network` states the rules): the slant range (with
    'depth'), the sound speed and one-way delay, the share of tau_data left to the data by the
    handshake (with 'propagation'), the node's E_req and what it pays for that window, the
    AET harvest (both by the compiled link budget: a transmission-loss table where the channel
    has one), the SNR at the AUV (the node's power makes it gamma_req = 2^(R/B) - 1; with no
    other uplink it is also the SINR), the PER at it (with 'packets'), the packets sent and
    those expected to arrive, and the bits expected per slot."""
    dz_m = node_depth_m - auv_depth_m if channel.on("depth") else 0.0
    range_m = float(np.hypot(horizontal_m, dz_m))
    c_mps = sound_speed_mps(channel)
    legs = channel.handshake_legs if channel.on("propagation") else 0
    window_s = max(cfg.data_s - legs * range_m / c_mps, 0.0)
    snr_db = required_snr_db(cfg)
    constants = ChannelConstants(channel, cfg)
    per = float(np.ravel(constants.packet_error_rate(snr_db))[0]) if channel.on("packets") else 0.0
    sent = math.floor(cfg.data_rate_bps * window_s / channel.packet_bits)
    auv_m, node_m = (auv_depth_m, node_depth_m) if channel.on("depth") else (0.0, 0.0)
    harvest_j, need_j = (
        float(e) for e in LinkBudget(cfg, channel).energies_j(horizontal_m, auv_m, node_m)
    )
    return {
        "horizontal_m": float(horizontal_m),
        "auv_depth_m": auv_depth_m if channel.on("depth") else 0.0,
        "node_depth_m": node_depth_m if channel.on("depth") else 0.0,
        "range_m": range_m,
        "sound_speed_mps": c_mps,
        "delay_s": range_m / c_mps,
        "usable_share": window_s / cfg.data_s,
        "harvest_energy_j": harvest_j,
        "uplink_energy_j": need_j,
        "uplink_cost_j": need_j * window_s / cfg.data_s,
        "snr_db": snr_db,
        "per": per,
        "packets_sent": float(sent) if channel.on("packets") else 0.0,
        "packets_expected": sent * (1.0 - per) if channel.on("packets") else 0.0,
        "bits_expected": (
            sent * (1.0 - per) * channel.packet_bits
            if channel.on("packets")
            else cfg.data_rate_bps * window_s
        ),
    }
