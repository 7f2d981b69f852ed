"""The acoustic network layer (`config.ChannelConfig`): hand-computed sound speed, PER and
interference; depth, the handshake's window, packets, fading; seeded, resumable, and the
paper's channel unchanged when every feature is off."""

import ctypes
import math
from typing import NamedTuple

import gymnasium as gym
import numpy as np
import pytest
from conftest import ROOT

from iout_mj import native
from iout_mj.config import AcousticsConfig, ChannelConfig, Config, NetworkConfig
from iout_mj.envs.batch import MissionBatch
from iout_mj.schema import ConfigError
from iout_mj.world import acoustics
from iout_mj.world.network import SensorNetwork

ALL = ("depth", "propagation", "packets", "interference", "fading")
NODES = [(100.0, 100.0), (900.0, 100.0)]


def channel(**fields):
    return ChannelConfig(**fields)


def network(ch: ChannelConfig, e0: float = 1.0) -> SensorNetwork:
    return SensorNetwork(
        NODES, NetworkConfig(node_initial_energy_j=e0), AcousticsConfig(), channel=ch
    )


class Links(NamedTuple):
    distance_m: np.ndarray
    uplink_ok: np.ndarray
    sinr_db: np.ndarray
    per: np.ndarray
    sent: np.ndarray
    received: np.ndarray


def serve(net: SensorNetwork, xy, data, draws=None, wet=None) -> Links:
    """One slot of the compiled rules through `net`'s channel; every AUV active."""
    xy = np.ascontiguousarray(xy, dtype=float)
    n, k = len(xy), net.n_nodes
    draws = np.zeros((n, 1 + 4 * n)) if draws is None else np.ascontiguousarray(draws, float)
    out = Links(
        np.zeros((n, k)), np.zeros(n, bool), np.zeros(n), np.zeros(n), *np.zeros((2, n), np.int64)
    )
    ints = [np.ascontiguousarray(a, np.int64) for a in (wet or data, data)]
    depths = [np.array(z, float) for z in net.channel_config.depths_m(n, k)]
    native.call(
        native.lib.iout_serve_channel,
        ctypes.addressof(net._struct),
        0,
        1,
        n,
        k,
        native.address(net.link.constants),
        native.address(net.channel.constants),
        net.cfg.k_reset,
        net.cfg.aoi_max,
        native.address(xy),
        *(native.address(a) for a in depths),
        *(native.address(a) for a in ints),
        native.address(np.ones(n, bool)),
        native.address(draws),
        *(native.address(a) for a in out),
    )
    return out


# ------------------------------------------------------------------ hand-computed values
def test_mackenzie_reproduces_his_check_value():
    assert acoustics.mackenzie_sound_speed_mps(25.0, 35.0, 1000.0) == pytest.approx(
        1550.744, abs=5e-4
    )
    # 0 m, 10 C, 35 ppt: 1448.96 + 45.91 - 5.304 + 0.2374
    assert acoustics.mackenzie_sound_speed_mps(10.0, 35.0, 0.0) == pytest.approx(1489.8034)


@pytest.mark.parametrize(
    ("modulation", "ber"),
    [("bpsk", 0.5 * math.erfc(2.0)), ("bfsk", 0.5 * math.exp(-2.0))],
)
def test_per_at_a_given_sinr_follows_the_ber_curve(modulation, ber):
    # R / B = 12: Eb/N0 = 4 (6.02 dB) at SINR 48 (16.81 dB)
    constants = acoustics.ChannelConstants(
        channel(features=("packets",), modulation=modulation, packet_bits=1000),
        AcousticsConfig(),
    )
    per = constants.packet_error_rate(10 * math.log10(48.0))
    assert per == pytest.approx(1 - (1 - ber) ** 1000, rel=1e-12)
    assert constants.packet_error_rate([60.0, -10.0]).tolist() == pytest.approx([0.0, 1.0])


def test_interference_of_two_known_links():
    ac = AcousticsConfig()
    net = network(channel(features=("interference", "packets")))
    xy = [(100.0, 300.0), (900.0, 400.0)]  # AUV 0 200 m over node 0, AUV 1 300 m over node 1
    links = serve(net, xy, data=[0, 1])

    def need(d):
        return float(acoustics.uplink_energy_j(d, ac))

    gamma = 2 ** (ac.data_rate_bps / ac.bandwidth_hz) - 1
    cross_0 = math.hypot(800.0, 200.0)  # node 1 to AUV 0
    cross_1 = math.hypot(800.0, 300.0)  # node 0 to AUV 1
    sinr_0 = gamma / (1 + gamma * need(300.0) / need(cross_0))
    sinr_1 = gamma / (1 + gamma * need(200.0) / need(cross_1))
    assert links.sinr_db == pytest.approx(10 * np.log10([sinr_0, sinr_1]), abs=1e-9)
    alone = serve(network(channel(features=("packets",))), xy, data=[0, 1])
    assert alone.sinr_db == pytest.approx([10 * math.log10(gamma)] * 2, abs=1e-9)


# ------------------------------------------------------------------ the features
def test_depth_makes_every_range_slant():
    ch = channel(features=("depth",), node_depth_m=100.0, auv_depth_m=40.0)
    links = serve(network(ch), [(100.0, 180.0)], data=[0])
    assert links.distance_m[0, 0] == pytest.approx(100.0)  # hypot(80, 60)
    cfg = Config(channel=ch)
    env = gym.make("iout_mj/MultiAUV-v0", backend="kinematic", config=cfg).unwrapped
    env.reset(seed=0)
    m = env.mission
    flat = np.hypot(*(m.state.positions_m[:, None, :] - m.network.nodes_m[None]).transpose(2, 0, 1))
    assert m.state.distance_m == pytest.approx(np.hypot(flat, 60.0))


def test_the_handshake_shortens_the_window_and_the_cost():
    ch = channel(features=("propagation", "packets"), handshake_legs=3)
    net = network(ch)
    d = 300.0
    e0 = float(net.energy_j[0])
    links = serve(net, [(100.0, 100.0 + d)], data=[0], wet=[1])
    c = acoustics.sound_speed_mps(ch)
    window_s = 25.0 - 3 * d / c
    assert links.sent[0] == math.floor(12_000 * window_s / 1000)
    assert links.received[0] == links.sent[0]  # SNR gamma_req = 36 dB: no packet lost
    assert e0 - net.energy_j[0] == pytest.approx(
        acoustics.uplink_energy_j(d, AcousticsConfig()) * window_s / 25.0
    )
    assert net.node_bits[0] == 1000 * links.sent[0]
    assert net.deliveries[0] == 1


def test_aoi_resets_only_on_a_delivery_that_arrived():
    # BFSK at the two links' ~0 dB SINR loses every packet; the nodes still pay for sending
    net = network(channel(features=("interference", "packets"), modulation="bfsk"))
    xy = [(500.0, 100.0), (500.0, 110.0)]  # both AUVs midway between the nodes
    e0 = net.energy_j.copy()
    for _ in range(4):
        links = serve(net, xy, data=[0, 1], draws=np.full((2, 9), 0.5))
        assert links.per.tolist() == [1.0, 1.0] and links.received.tolist() == [0, 0]
        assert links.sent.min() > 0 and not links.uplink_ok.any()
    assert net.deliveries.tolist() == [0, 0] and net.aoi.tolist() == [5.0, 5.0]
    assert net.node_bits.tolist() == [0.0, 0.0]
    d = np.array([400.0, math.hypot(400.0, 10.0)])  # each AUV charges its own node too
    paid = acoustics.uplink_energy_j(d, AcousticsConfig())
    harvested = acoustics.harvest_energy_j(d, AcousticsConfig())
    assert net.energy_j == pytest.approx(e0 + 4 * (harvested - paid))


def test_rayleigh_fading_has_unit_mean_power_and_an_exponential_law():
    net = network(channel(features=("fading",)), e0=1e9)
    gamma = 2**12 - 1
    rng = np.random.RandomState(3)
    gains = [
        10
        ** (serve(net, [(100.0, 200.0)], data=[0], draws=rng.random_sample((1, 5))).sinr_db[0] / 10)
        / gamma
        for _ in range(4000)
    ]
    assert np.mean(gains) == pytest.approx(1.0, abs=0.05)
    assert np.mean(np.less(gains, 1.0)) == pytest.approx(1 - math.exp(-1), abs=0.025)


def test_shadowing_is_log_normal_with_its_sigma():
    ch = channel(
        features=("fading",), fading_model="rician", rician_k_db=40.0, shadowing_sigma_db=6.0
    )
    net = network(ch, e0=1e9)
    rng = np.random.RandomState(4)
    db = [
        serve(net, [(100.0, 200.0)], data=[0], draws=rng.random_sample((1, 5))).sinr_db[0]
        for _ in range(3000)
    ]
    gamma_db = 10 * math.log10(2**12 - 1)
    assert np.mean(db) - gamma_db == pytest.approx(0.0, abs=0.4)  # K = 40 dB: nearly no fading
    assert np.std(db) == pytest.approx(6.0, rel=0.06)


# ------------------------------------------------------------------ the env
def run(config, seed=0, slots=30):
    env = gym.make("iout_mj/MultiAUV-v0", backend="kinematic", config=config)
    env.reset(seed=seed)
    env.action_space.seed(seed)
    out = []
    for _ in range(slots):
        _, reward, terminated, truncated, info = env.step(env.action_space.sample())
        out.append((reward, info.get("channel")))
        if terminated or truncated:
            break
    return out


def test_no_feature_and_flat_depths_leave_the_paper_channel_as_it_is():
    paper = run(None)
    # the channel's own path with nothing that changes the outcome: depth with dz = 0
    flat = run({"channel": {"features": ["depth"], "node_depth_m": 50.0, "auv_depth_m": 50.0}})
    assert [r for r, _ in flat] == [r for r, _ in paper]
    assert all(info is None for _, info in paper)


def test_the_realistic_channel_is_seeded():
    config = {"channel": {"features": list(ALL), "shadowing_sigma_db": 4.0}}
    first, again, other = run(config, 1), run(config, 1), run(config, 2)
    assert repr(first) == repr(again)
    assert repr(first) != repr(other)
    assert any(info["packets_sent"] != [0, 0] for _, info in first)


def test_a_saved_batch_resumes_the_channel_exactly():
    config = Config.from_dict({"channel": {"features": list(ALL), "shadowing_sigma_db": 4.0}})
    actions = np.random.RandomState(0).randint(0, 7, size=(20, 3, 8))
    a, b = MissionBatch(3, config=config, seed=5), MissionBatch(3, config=config, seed=9)
    a.restart()
    b.restart()
    for t in range(8):
        a.step(actions[t])
    b.load_state_arrays(a.state_arrays())
    for t in range(8, 20):
        sa, sb = a.step(actions[t]), b.step(actions[t])
        assert sa.rewards.tolist() == sb.rewards.tolist()
    assert a.mission.network.node_bits.tolist() == b.mission.network.node_bits.tolist()


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"channel": {"features": ["depth", "multipath"]}}, "distinct names among 'depth'"),
        ({"channel": {"features": ["packets"], "packet_bits": 100}}, "fits 1 to 1000 packets"),
        (
            {"channel": {"features": ["interference"]}, "acoustics": {"f_wet_khz": 50.2}},
            "outside the data band",
        ),
        ({"channel": {"auv_depth_m": 200.0}}, "at most the shallowest node's seabed, 100 m"),
    ],
)
def test_bad_channel_configs_say_what_is_accepted(data, message):
    with pytest.raises(ConfigError, match=message):
        Config.from_dict(data)


def test_the_shipped_realistic_channel_turns_every_feature_on():
    cfg = Config.load(ROOT / "training" / "configs" / "env" / "realistic-channel.yaml")
    assert set(cfg.channel.features) == set(ALL)
    assert cfg.acoustics == AcousticsConfig() and cfg.scenario == Config().scenario
    steps = run(cfg, seed=3, slots=55)
    assert {"sinr_db", "per", "packets_sent", "packets_received"} == set(steps[0][1])
    sent = sum(sum(info["packets_sent"]) for _, info in steps)
    received = sum(sum(info["packets_received"]) for _, info in steps)
    assert 0 < received <= sent
