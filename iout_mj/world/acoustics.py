"""Acoustic link budget: Thorp absorption, sonar equation, AET harvest and uplink energy (numpy).

The combination implemented (DESIGN.md section 4; the paper's symbols):

- alpha(f) [dB/km], f in kHz: Thorp (paper eq. 3).
- TL(d) = k_s * 10 log10(max(d, 1 m)) + alpha(f) * d / 1000.
- SL = 170.8 + 10 log10(P_elec) + 10 log10(eta_tx) + DI_tx.
- AET: RL = SL - TL + DI_rx and P_harv = eta_harv * n_hyd * 10^((RL + RVS)/10) / (4 R_p).
  The paper writes RL = SL - AL - NL; ambient noise does not reduce the acoustic power a
  harvester collects, so the noise term is used for the uplink only.
- Uplink: gamma_req = 10 log10(2^(R/B) - 1); NL_band = NL(f_data) + 10 log10(B);
  SL_req = gamma_req + TL + NL_band; P_trans = 10^((SL_req - 170.8 - 10 log10 eta_tx - DI_tx)/10).

All functions take scalars or arrays of distances (any shape, e.g. AUVs x nodes).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from iout_mj import native
from iout_mj.config import AcousticsConfig
from iout_mj.types import FloatArray

SL_REF_DB = 170.8
"""Source level of 1 W of acoustic power radiated omnidirectionally, dB re 1 uPa at 1 m."""
MIN_DISTANCE_M = 1.0
"""Transmission loss is referred to 1 m; closer distances count as 1 m."""


def thorp_absorption_db_per_km(f_khz: ArrayLike) -> FloatArray:
    """Thorp's absorption coefficient alpha(f) in dB/km for f in kHz."""
    f2 = np.square(np.asarray(f_khz, dtype=float))
    return 0.11 * f2 / (1 + f2) + 44 * f2 / (4100 + f2) + 2.75e-4 * f2 + 0.003


def transmission_loss_db(
    distance_m: ArrayLike, f_khz: float, spreading_factor: float
) -> FloatArray:
    """TL = k_s * 10 log10(d) + alpha(f) d/1000, with d in metres (at least 1 m)."""
    d = np.maximum(np.asarray(distance_m, dtype=float), MIN_DISTANCE_M)
    return spreading_factor * 10 * np.log10(d) + thorp_absorption_db_per_km(f_khz) * d / 1000


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


def harvest_power_w(distance_m: ArrayLike, cfg: AcousticsConfig) -> FloatArray:
    """Electrical power harvested by a node at `distance_m` from the AET projector."""
    sl = source_level_db(cfg.p_tx_w, cfg.eta_tx, cfg.di_tx_db)
    rl = sl - transmission_loss_db(distance_m, cfg.f_wet_khz, cfg.spreading_factor) + cfg.di_rx_db
    return (
        cfg.eta_harv
        * cfg.n_hydrophones
        * 10 ** ((rl + cfg.rvs_db) / 10)
        / (4 * cfg.load_resistance_ohm)
    )


def required_snr_db(cfg: AcousticsConfig) -> float:
    """Shannon-bound SNR for rate R over bandwidth B: 10 log10(2^(R/B) - 1)."""
    return float(10 * np.log10(2 ** (cfg.data_rate_bps / cfg.bandwidth_hz) - 1))


def uplink_power_w(distance_m: ArrayLike, cfg: AcousticsConfig) -> FloatArray:
    """Electrical transmit power a node needs to reach an AUV at `distance_m` at rate R."""
    nl_band = noise_psd_db(cfg.f_data_khz, cfg) + 10 * np.log10(cfg.bandwidth_hz)
    tl = transmission_loss_db(distance_m, cfg.f_data_khz, cfg.spreading_factor)
    sl_req = required_snr_db(cfg) + tl + nl_band
    return 10 ** ((sl_req - SL_REF_DB - 10 * np.log10(cfg.eta_tx) - cfg.di_tx_db) / 10)


def harvest_energy_j(distance_m: ArrayLike, cfg: AcousticsConfig) -> FloatArray:
    """Energy harvested over one charging period tau_charging."""
    return harvest_power_w(distance_m, cfg) * cfg.charging_s


def uplink_energy_j(distance_m: ArrayLike, cfg: AcousticsConfig) -> FloatArray:
    """Energy E_req a node spends to deliver one update over tau_data."""
    return uplink_power_w(distance_m, cfg) * cfg.data_s


LINK_DTYPE = native.record_dtype("Link")
"""The link budget's distance-independent constants (`LinkBudget`), as the compiled rules
read them (native.h's IOUT_LINK)."""


class LinkBudget(native.Frozen):
    """The same link budget with every distance-independent term folded into a constant, for
    the per-slot hot path: per distance, one power and two exponentials.

    harvest(d) = c_h d^-k_s 10^(-alpha_wet d / 10^4)
    uplink(d) = c_u d^k_s 10^(alpha_data d / 10^4)
    """

    def __init__(self, cfg: AcousticsConfig):
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
            "wet_per_m": -float(thorp_absorption_db_per_km(cfg.f_wet_khz)) * ln10 / 1e4,
            "data_per_m": float(thorp_absorption_db_per_km(cfg.f_data_khz)) * ln10 / 1e4,
            "spreading": cfg.spreading_factor,
            "min_distance_m": MIN_DISTANCE_M,
        }
        native.require_names("Link", tuple(sorted(LINK_DTYPE.names or ())), tuple(sorted(values)))
        constants = native.allocate((1,), LINK_DTYPE)
        for name, value in values.items():
            constants[name] = value
        self.constants = native.read_only(constants)
        """(1,) record of LINK_DTYPE (read-only: the compiled rules read it)."""
        self._freeze()

    def energies_j(self, distance_m: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(harvested energy per slot, uplink energy E_req) at each distance (any shape), by
        the compiled `iout_link_energies` that the slot rules use."""
        d = np.ascontiguousarray(distance_m, dtype=float)
        harvest, uplink = np.empty_like(d), np.empty_like(d)
        native.call(
            native.lib.iout_link_energies,
            native.address(self.constants),
            native.address(d),
            d.size,
            native.address(harvest),
            native.address(uplink),
        )
        return harvest, uplink


def bits_per_delivery(cfg: AcousticsConfig) -> float:
    """Data delivered by one successful uplink: R * tau_data."""
    return cfg.data_rate_bps * cfg.data_s
