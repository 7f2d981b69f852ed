"""Link budget against values computed by hand (paper Table II, DESIGN.md section 4)."""

import numpy as np
import pytest

from iout_mj.config import AcousticsConfig
from iout_mj.world import acoustics

CFG = AcousticsConfig()


@pytest.mark.parametrize(
    ("f_khz", "expected"),
    [
        # 0.11 f2/(1+f2) + 44 f2/(4100+f2) + 2.75e-4 f2 + 0.003, f2 = f^2
        (50.0, 0.109956 + 16.666667 + 0.6875 + 0.003),  # 17.46712 dB/km
        (70.0, 0.109978 + 23.955556 + 1.3475 + 0.003),  # 25.41603 dB/km
        (1.0, 0.055 + 0.010729 + 0.000275 + 0.003),
    ],
)
def test_thorp(f_khz, expected):
    assert acoustics.thorp_absorption_db_per_km(f_khz) == pytest.approx(expected, abs=1e-5)


@pytest.mark.parametrize(
    ("d_m", "f_khz", "expected"),
    [
        (10.0, 50.0, 15.0 + 0.174671),  # 1.5*10*log10(10) + 17.46712*0.01
        (100.0, 70.0, 30.0 + 2.541603),  # 1.5*20 + 25.41603*0.1
        (500.0, 50.0, 40.484550 + 8.733562),
        (0.2, 50.0, 0.0 + 0.017467),  # closer than 1 m counts as 1 m for spreading
    ],
)
def test_transmission_loss(d_m, f_khz, expected):
    got = acoustics.transmission_loss_db(d_m, f_khz, 1.5)
    assert got == pytest.approx(expected, abs=1e-5)


def test_source_level():
    # 170.8 + 10 log10(5) + 10 log10(0.7) + 10 = 170.8 + 6.989700 - 1.549020 + 10
    assert acoustics.source_level_db(5.0, 0.7, 10.0) == pytest.approx(186.240680, abs=1e-5)


@pytest.mark.parametrize(
    ("d_m", "harvest_w"),
    [
        # RL = 186.240680 - TL(d, 70 kHz) + 10; P = 0.7 * 4 * 10^((RL - 150)/10) / (4 * 125)
        (100.0, 0.7 * 4 * 10 ** ((186.240680 - 32.541603 + 10 - 150) / 10) / 500),  # 0.131244 W
        (10.0, 0.7 * 4 * 10 ** ((186.240680 - 15.254160 + 10 - 150) / 10) / 500),  # 7.0277 W
        (500.0, 0.7 * 4 * 10 ** ((186.240680 - 53.192567 + 10 - 150) / 10) / 500),  # 1.1297 mW
    ],
)
def test_harvest(d_m, harvest_w):
    assert acoustics.harvest_power_w(d_m, CFG) == pytest.approx(harvest_w, rel=1e-5)
    assert acoustics.harvest_energy_j(d_m, CFG) == pytest.approx(25 * harvest_w, rel=1e-5)


def test_harvest_at_100m_is_about_3_3_joules_per_slot():
    assert acoustics.harvest_energy_j(100.0, CFG) == pytest.approx(3.281, abs=1e-3)


@pytest.mark.parametrize(
    ("d_m", "tl_db"), [(100.0, 31.746712), (10.0, 15.174671), (500.0, 49.218112)]
)
def test_uplink(d_m, tl_db):
    # gamma = 10 log10(2^12 - 1) = 36.122539; NL_band = 40 + 30; SL_req = gamma + TL + 70
    sl_req = 36.122539 + tl_db + 70.0
    p = 10 ** ((sl_req - 170.8 + 1.549020 - 10) / 10)
    assert acoustics.uplink_power_w(d_m, CFG) == pytest.approx(p, rel=1e-5)
    assert acoustics.uplink_energy_j(d_m, CFG) == pytest.approx(25 * p, rel=1e-5)


def test_uplink_at_100m_is_about_1_8_millijoules():
    assert acoustics.uplink_energy_j(100.0, CFG) == pytest.approx(1.819e-3, rel=1e-3)


def test_noise_flat_and_wenz():
    assert acoustics.noise_psd_db(50.0, CFG) == pytest.approx(40.0)
    wenz = AcousticsConfig(noise_model="wenz", shipping_activity=0.5, wind_speed_mps=0.0)
    # At 50 kHz: turbulence -33.969, shipping -17.781, wind 15.882, thermal 18.979 dB;
    # 10 log10(sum 10^(N/10)) = 10 log10(0.000401 + 0.016667 + 38.745 + 79.060) = 20.7121
    assert acoustics.noise_psd_db(50.0, wenz) == pytest.approx(20.7121, abs=2e-3)
    windy = AcousticsConfig(noise_model="wenz", wind_speed_mps=10.0)
    assert acoustics.noise_psd_db(50.0, windy) > acoustics.noise_psd_db(50.0, wenz)


def test_vectorised_over_auvs_by_nodes():
    d = np.array([[10.0, 100.0, 500.0], [100.0, 500.0, 10.0]])
    out = acoustics.uplink_energy_j(d, CFG)
    assert out.shape == (2, 3)
    assert out[0, 1] == pytest.approx(acoustics.uplink_energy_j(100.0, CFG))
    assert np.all(np.diff(acoustics.harvest_power_w([10, 100, 500, 1000], CFG)) < 0)


@pytest.mark.parametrize("noise", ["flat", "wenz"])
def test_link_budget_fast_path_matches_the_equations(noise):
    cfg = AcousticsConfig(noise_model=noise, wind_speed_mps=5.0)
    d = np.array([[0.5, 10.0, 100.0], [333.0, 1000.0, 2500.0]])
    harvest, uplink = acoustics.LinkBudget(cfg).energies_j(d)
    np.testing.assert_allclose(harvest, acoustics.harvest_energy_j(d, cfg), rtol=1e-12)
    np.testing.assert_allclose(uplink, acoustics.uplink_energy_j(d, cfg), rtol=1e-12)
