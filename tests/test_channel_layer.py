"""The acoustic network layer's second part: Francois-Garrison absorption, per-AUV and per-node
depths, the link budget by range and depth, the mission trace, and the channel in every env."""

import csv
import json

import gymnasium as gym
import numpy as np
import pytest
from conftest import ROOT

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
    # training from the file keeps its depths (train --nodes-file)
    from iout_mj.cli import build_parser
    from iout_mj.commands import train_overrides
    from iout_mj.training import TrainConfig

    args = build_parser().parse_args(["train", "x.yaml", "--nodes-file", str(path)])
    cfg = train_overrides(TrainConfig.load(ROOT / "training/configs/smoke.yaml"), args)
    assert cfg.env.channel.node_depths_m == (80.0, 120.0, 90.0)
    assert cfg.env.scenario.nodes_m[2] == (500.0, 800.0)


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


# ------------------------------------------------------------------ the mission trace
@pytest.mark.parametrize("features", [[], ["depth", "propagation", "packets", "fading"]])
def test_a_five_slot_trace_has_every_link_and_the_missions_bits(tmp_path, features):
    from iout_mj.experiments.mission import TRACE_COLUMNS, run_mission

    cfg = Config.from_dict({"channel": {"features": features}})
    summary = run_mission(
        "planner",
        cfg,
        "kinematic",
        seed=1,
        out=tmp_path,
        video=False,
        slots=5,
        trace_path=tmp_path / "trace",
    )
    with (tmp_path / "trace.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == TRACE_COLUMNS
    assert [(int(r["slot"]), int(r["auv"])) for r in rows] == [
        (t, i) for t in range(1, 6) for i in range(2)
    ]
    bits = sum(float(r["bits_delivered"]) for r in rows)
    assert bits == pytest.approx(summary["metrics"]["delivered_bits"]) and bits > 0
    nested = json.loads((tmp_path / "trace.json").read_text())["slots"]
    assert [s["slot"] for s in nested] == [1, 2, 3, 4, 5] and len(nested[0]["nodes"]) == 7
    assert sum(n["bits_delivered"] for s in nested for n in s["nodes"]) == pytest.approx(bits)
    depth = 50.0 if features else 0.0
    assert {float(r["auv_depth_m"]) for r in rows} == {depth}
    if features:  # the channel's per-link outcomes; packets arrive for the bits
        sent = [int(r["packets_sent"]) for r in rows]
        assert all(r["sinr_db"] != "" for r in rows if int(r["packets_sent"]))
        assert sum(int(r["packets_received"]) for r in rows) * 1000 >= bits > 0 < sum(sent)
    else:
        assert all(r["sinr_db"] == "" and r["packets_sent"] == "0" for r in rows)


# ------------------------------------------------------------------ iout-mj link-budget
def link_budget(capsys, *args: str) -> str:
    from iout_mj.cli import main

    assert main(["link-budget", *args]) == 0
    return capsys.readouterr().out


def test_link_budget_prints_the_channel_by_range_and_depth(capsys, tmp_path):
    paper = link_budget(capsys, "--distance", "100", "300")
    assert "channel:" not in paper and "absorption" not in paper
    path = tmp_path / "env.yaml"
    cfg = Config.from_dict(
        {
            "scenario": {"nodes_m": [[100, 100, 80], [900, 100, 120]]},
            "channel": {"features": ["depth", "propagation", "packets"], "auv_depth_m": 40.0},
        }
    )
    cfg.save(path)
    text = link_budget(capsys, "--config", str(path), "--distance", "100", "300")
    assert text.startswith(paper.splitlines()[0]) and "PER" in text
    data = json.loads(
        link_budget(capsys, "--config", str(path), "--distance", "100", "300", "--json")
    )
    assert [r["distance_m"] for r in data["link"]] == [100.0, 300.0]
    links = data["channel"]
    assert [(r["horizontal_m"], r["node_depth_m"]) for r in links] == [
        (100.0, 80.0),
        (100.0, 120.0),
        (300.0, 80.0),
        (300.0, 120.0),
    ]
    r = links[1]
    c = float(acoustics.mackenzie_sound_speed_mps(10.0, 35.0, 0.5 * (40.0 + 100.0)))
    assert r["range_m"] == pytest.approx(np.hypot(100.0, 80.0))
    assert r["sound_speed_mps"] == pytest.approx(c) and r["delay_s"] == pytest.approx(
        r["range_m"] / c
    )
    assert r["usable_share"] == pytest.approx(1 - 3 * r["delay_s"] / 25.0)
    assert r["snr_db"] == pytest.approx(10 * np.log10(2.0**12 - 1))
    assert r["packets_sent"] == np.floor(12000 * 25.0 * r["usable_share"] / 1000)
    assert r["packets_expected"] == pytest.approx(r["packets_sent"] * (1 - r["per"]))
    need = float(acoustics.uplink_energy_j(r["range_m"], AcousticsConfig()))
    assert r["uplink_cost_j"] == pytest.approx(need * r["usable_share"])


# ------------------------------------------------------------------ every env
REALISTIC = {
    "channel": {
        "features": ["depth", "propagation", "packets", "interference", "fading"],
        "modulation": "bfsk",
        "packet_bits": 2048,
        "fading_model": "rician",
        "shadowing_sigma_db": 3.0,
    }
}


def assert_batch_of_one_matches_the_single_env(venv, backend, cfg, rng, steps):
    """A batch draws every env's channel uniforms from its one task RNG, in env order; a batch
    of one seeded like a single env therefore draws what that env draws, slot by slot."""
    single = gym.make("iout_mj/MultiAUV-v0", backend=backend, config=cfg)
    obs = venv.reset()
    np.testing.assert_array_equal(obs[0], single.reset(seed=0)[0])
    bits = 0.0
    for _ in range(steps):
        actions = rng.integers(0, venv.action_space.nvec, size=(1, venv.action_space.shape[0]))
        obs, rewards, dones, infos = venv.step(actions)
        o, r, *_, info = single.step(actions[0])
        assert rewards[0] == pytest.approx(r, rel=1e-9, abs=1e-9)
        if dones[0]:
            assert infos[0]["metrics"]["delivered_bits"] == info["metrics"]["delivered_bits"]
            bits += info["metrics"]["delivered_bits"]
            o, _ = single.reset()
        np.testing.assert_allclose(obs[0], o, atol=1e-6)
    assert bits > 0


def test_the_channel_in_the_kinematic_batch_matches_the_single_env(rng):
    from iout_mj.envs import KinematicVecEnv

    cfg = Config.from_dict(REALISTIC)
    venv = KinematicVecEnv(1, config=cfg, seed=0)
    assert_batch_of_one_matches_the_single_env(venv, "kinematic", cfg, rng, 120)


@pytest.mark.slow
def test_the_channel_in_the_physics_batch_matches_the_single_env(rng):
    from iout_mj.envs import PhysicsVecEnv

    cfg = Config.from_dict(REALISTIC)
    venv = PhysicsVecEnv(1, config=cfg, nthread=1, seed=0)
    assert_batch_of_one_matches_the_single_env(venv, "mujoco", cfg, rng, 60)
    venv.close()


def test_the_channel_in_the_parallel_env_matches_the_gym_env():
    import iout_mj

    cfg = Config.from_dict(REALISTIC)
    env = iout_mj.parallel_env(config=cfg)
    single = gym.make("iout_mj/MultiAUV-v0", backend="kinematic", config=cfg)
    env.reset(seed=4)
    single.reset(seed=4)
    received = 0
    space = env.action_space("auv_0")
    space.seed(0)
    while env.agents:
        actions = {a: space.sample() for a in env.agents}
        _, rewards, *_ = env.step(actions)
        flat, reward, *_, info = single.step(np.concatenate([actions["auv_0"], actions["auv_1"]]))
        np.testing.assert_array_equal(env.state(), flat)
        assert rewards["auv_0"] == reward
        received += sum(info["channel"]["packets_received"])
    assert received > 0


def test_the_tour_scheduler_sends_one_uplink_per_slot_under_interference():
    """Two uplinks of a slot drown each other (SINR ~0 dB against gamma_req = 36 dB): with
    interference on, both AUVs name one node, whose packets then arrive."""
    from iout_mj.agents.policies import load_policy

    env = gym.make("iout_mj/MultiAUV-v0", backend="kinematic", config=Config.from_dict(REALISTIC))
    act = load_policy("tour-scheduler", env, 0)
    obs, _ = env.reset(seed=0)
    sent = received = 0
    for _ in range(12):
        obs, *_, info = env.step(act(env, obs))
        uplinks = env.unwrapped.mission.state.action[:, 3]
        assert uplinks[0] == uplinks[1]
        sent += info["channel"]["packets_sent"][0]
        received += info["channel"]["packets_received"][0]
    assert received >= 0.9 * sent > 0
