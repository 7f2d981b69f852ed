"""The acoustic network layer's second part: Francois-Garrison absorption, per-AUV and per-node
depths, the link budget by range and depth, the mission trace, and the channel in every env."""

import gymnasium as gym
import numpy as np
import pytest

from iout_mj.config import AcousticsConfig, ChannelConfig, Config
from iout_mj.scenarios import resolve
from iout_mj.schema import ConfigError
from iout_mj.world import acoustics

FG = "francois-garrison"


def test_francois_garrison_at_published_value():
    """Fisher and Simmons (1977, J. Acoust. Soc. Am. 62(3), Table IV) give 0.52 dB/km at 10 kHz,
    4 C, 35 ppt and 500 atm (4990 dbar, about 4900 m); Francois and Garrison's equation agrees
    within the ~10 % by which the published formulations differ (the oce package's notes on
    swSoundAbsorption)."""
    alpha = acoustics.francois_garrison_absorption_db_per_km(10.0, 4.0, 35.0, 4900.0, 8.0)
    assert float(alpha[()]) == pytest.approx(0.52, rel=0.15)


def test_francois_garrison_terms_by_hand():
    """The three relaxations at 50 kHz, 10 C, 35 ppt, 75 m, pH 8, each computed here."""
    f, t, s, z, ph = 50.0, 10.0, 35.0, 75.0, 8.0
    c, theta = 1412 + 3.21 * t + 1.19 * s + 0.0167 * z, 273 + t
    f1 = 2.8 * np.sqrt(s / 35) * 10 ** (4 - 1245 / theta)
    boric = 8.86 / c * 10 ** (0.78 * ph - 5) * f1 * f**2 / (f1**2 + f**2)
    f2 = 8.17 * 10 ** (8 - 1990 / theta) / (1 + 0.0018 * (s - 35))
    p2 = 1 - 1.37e-4 * z + 6.2e-9 * z**2
    mgso4 = 21.44 * s / c * (1 + 0.025 * t) * p2 * f2 * f**2 / (f2**2 + f**2)
    a3 = 4.937e-4 - 2.59e-5 * t + 9.11e-7 * t**2 - 1.5e-8 * t**3
    water = a3 * (1 - 3.83e-5 * z + 4.9e-10 * z**2) * f**2
    got = acoustics.francois_garrison_absorption_db_per_km(f, t, s, z, ph)
    assert float(got[()]) == pytest.approx(boric + mgso4 + water, rel=1e-12)
    assert float(got[()]) == pytest.approx(15.229, abs=1e-3)


def test_francois_garrison_same_order_as_thorp_and_falls_with_depth():
    f = np.array([10.0, 20.0, 30.0, 50.0])
    fg = acoustics.francois_garrison_absorption_db_per_km(f, 10.0, 35.0, 75.0)
    ratio = fg / acoustics.thorp_absorption_db_per_km(f)
    assert np.all((ratio > 0.7) & (ratio < 1.1))  # 0.80 to 0.88 here
    deep = acoustics.francois_garrison_absorption_db_per_km(f, 10.0, 35.0, 3000.0)
    assert np.all(deep < fg)  # pressure relaxes the MgSO4 term


def test_absorption_model_in_the_link_budget():
    ac = AcousticsConfig()
    d = np.array([10.0, 200.0, 800.0])
    paper = acoustics.LinkBudget(ac).constants.tobytes()
    assert acoustics.LinkBudget(ac, ChannelConfig()).constants.tobytes() == paper
    ch = ChannelConfig(absorption=FG, node_depth_m=100.0, auv_depth_m=50.0)
    harvest, uplink = acoustics.LinkBudget(ac, ch).energies_j(d)
    np.testing.assert_allclose(harvest, acoustics.harvest_energy_j(d, ac, ch), rtol=1e-12)
    np.testing.assert_allclose(uplink, acoustics.uplink_energy_j(d, ac, ch), rtol=1e-12)
    assert np.all(uplink[1:] < acoustics.uplink_energy_j(d[1:], ac)[()])  # FG absorbs less
    alpha = acoustics.francois_garrison_absorption_db_per_km(50.0, 10.0, 35.0, 75.0)
    tl = 1.5 * 10 * np.log10(800.0) + float(alpha[()]) * 0.8
    assert float(acoustics.transmission_loss_db(800.0, 50.0, 1.5, ch)) == pytest.approx(tl)


def test_absorption_refusals():
    with pytest.raises(ConfigError, match=r"absorption.*'thorp', 'francois-garrison'"):
        ChannelConfig(absorption="fisher-simmons")
    with pytest.raises(ConfigError, match=r"temperature_degc.*\[-2, 22\].*Francois"):
        ChannelConfig(absorption=FG, temperature_degc=25.0)
    with pytest.raises(ConfigError, match=r"ph.*\[7\.7, 8\.3\]"):
        Config.from_dict({"channel": {"ph": 9.0}})


# ------------------------------------------------------------------ depths
def slant_env(cfg: Config):
    env = gym.make("iout_mj/MultiAUV-v0", backend="kinematic", config=cfg).unwrapped
    env.reset(seed=0)
    m = env.mission
    flat = np.hypot(*(m.state.positions_m[:, None, :] - m.network.nodes_m[None]).transpose(2, 0, 1))
    return m, flat


def test_per_auv_and_per_node_depths_make_each_range_slant():
    nodes = [[100.0, 100.0, 80.0], [900.0, 100.0, 120.0], [500.0, 800.0, 100.0]]
    data = {"scenario": {"nodes_m": nodes}, "channel": {"features": ["depth"]}}
    cfg = Config.from_dict({**data, "channel": {"features": ["depth"], "auv_depths_m": [20, 60]}})
    assert cfg.channel.node_depths_m == (80.0, 120.0, 100.0)
    assert cfg.scenario.nodes_m == ((100.0, 100.0), (900.0, 100.0), (500.0, 800.0))
    m, flat = slant_env(cfg)
    dz = np.array([[60.0, 100.0, 80.0], [20.0, 60.0, 40.0]])  # node z - AUV z
    np.testing.assert_allclose(m.state.distance_m, np.hypot(flat, dz), rtol=1e-12)
    one = Config.from_dict({**data, "channel": {"features": ["depth"], "auv_depth_m": 30.0}})
    m, flat = slant_env(one)
    np.testing.assert_allclose(m.state.distance_m, np.hypot(flat, [50.0, 90.0, 70.0]))
    off = Config.from_dict({"scenario": {"nodes_m": nodes}})  # z kept, depth off: horizontal
    m, flat = slant_env(off)
    assert np.array_equal(m.state.distance_m, flat)


def test_a_nodes_file_with_depths(tmp_path):
    path = tmp_path / "nodes.csv"
    path.write_text("x, y, z  # z: seabed depth\n100, 100, 80\n900, 100, 120\n500, 800, 90\n")
    spec = resolve(nodes=path)
    assert spec.config.channel.node_depths_m == (80.0, 120.0, 90.0)
    assert spec.config.scenario.nodes_m[2] == (500.0, 800.0)
    flat = tmp_path / "flat.csv"
    flat.write_text("100, 100\n900, 100\n")
    assert resolve(nodes=flat).config.channel.node_depths_m == ()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("100, 100, -5\n900, 100, 50\n", "node 0 has z=-5, above the surface; accepted a seabed"),
        ("100, 100, 50\n900, 100\n", r"2 values; accepted 'x, y' or 'x, y, z'"),
        ("100, 100, 50, 1\n900, 100, 50, 1\n", r"4 values; accepted 'x, y' or 'x, y, z'"),
    ],
)
def test_bad_nodes_files_say_what_is_accepted(tmp_path, text, message):
    path = tmp_path / "nodes.csv"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        resolve(nodes=path)


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"scenario": {"nodes_m": [[100, 100, 50], [900, 100]]}}, r"every row \(x, y\) or"),
        ({"scenario": {"nodes_m": [[100, 100, -1], [900, 100, 9]]}}, "positive down"),
        ({"channel": {"node_depths_m": [100.0, 90.0]}}, r"one depth per node of .*\(7\)"),
        ({"channel": {"auv_depths_m": [10.0]}}, r"at least one depth per AUV \(scenario.n_auvs=2"),
        ({"channel": {"auv_depths_m": [10.0, 120.0]}}, "shallowest node's seabed, 100 m"),
    ],
)
def test_bad_depths_say_what_is_accepted(data, message):
    with pytest.raises(ConfigError, match=message):
        Config.from_dict(data)
