"""A site-specific transmission-loss table in the link budget (`channel.transmission_loss_file`):
a synthetic table whose TL is a known function of range and depth gives the hand-computed AET
harvest and uplink energy in the compiled slot, the planners' link budget and the link-budget
command; a kinematic mission flies with it (a batch of one equals the single env); tables the
link budget cannot use are refused with what is accepted; BELLHOP's table end to end when
pelagic is installed."""

import dataclasses
import importlib.util
import json
import math

import gymnasium as gym
import numpy as np
import pytest
from conftest import ROOT
from test_channel import serve

from iout_mj import cli
from iout_mj.config import AcousticsConfig, ChannelConfig, Config, NetworkConfig
from iout_mj.envs import ENV_ID, KinematicVecEnv
from iout_mj.mission.core import Mission
from iout_mj.scenarios import load_config, make_config
from iout_mj.schema import ConfigError
from iout_mj.world import acoustics
from iout_mj.world.network import SensorNetwork
from iout_mj.world.tl_table import (
    TLTable,
    TLTableError,
    link_bounds,
    load_table,
    save_table,
)

REALISTIC = ROOT / "training/configs/env/realistic-channel.yaml"
RANGES_M = np.array([10.0, 500.0, 1000.0, 1500.0])
DEPTHS_M = np.array([10.0, 50.0, 90.0])


def known_tl_db(f_khz: float, range_m, depth_m):
    """The synthetic TL: linear in range and depth (bilinear interpolation is exact), a few dB
    more at the AET's 70 kHz than at the data's 50 kHz."""
    return 30.0 + 0.1 * f_khz + 0.03 * np.asarray(range_m) + 0.05 * np.asarray(depth_m)


def synthetic(frequencies=(50.0, 70.0), depths=DEPTHS_M, ranges=RANGES_M, source=99.5):
    r, z = np.meshgrid(ranges, depths)
    tl = np.stack([known_tl_db(f, r, z) for f in frequencies])
    return TLTable(list(frequencies), depths, ranges, tl, source)


@pytest.fixture
def table_file(tmp_path):
    path = tmp_path / "site.npz"
    save_table(synthetic(), path)
    return path


def with_table(path, **fields) -> ChannelConfig:
    return ChannelConfig(features=("depth",), transmission_loss_file=str(path), **fields)


def hand_harvest_j(tl_db: float) -> float:
    """Paper's AET with TL given: SL = 170.8 + 10 log10(5 W) + 10 log10(0.7) + 10 dB,
    RL = SL - TL + 10 dB, P = 0.7 x 4 x 10^((RL - 150) / 10) / (4 x 125 ohm), over 25 s."""
    sl = 170.8 + 10 * math.log10(5.0) + 10 * math.log10(0.7) + 10.0
    return 25.0 * 0.7 * 4 * 10 ** ((sl - tl_db + 10.0 - 150.0) / 10) / (4 * 125.0)


def hand_uplink_j(tl_db: float) -> float:
    """Paper's uplink with TL given: SL_req = 10 log10(2^12 - 1) + TL + 40 + 30 dB, P =
    10^((SL_req - 170.8 - 10 log10(0.7) - 10) / 10), over 25 s."""
    sl_req = 10 * math.log10(2**12 - 1) + tl_db + 40.0 + 30.0
    return 25.0 * 10 ** ((sl_req - 170.8 - 10 * math.log10(0.7) - 10.0) / 10)


@pytest.mark.parametrize("range_m", [100.0, 250.0, 700.0, 1200.0])
@pytest.mark.parametrize("auv_depth_m", [20.0, 50.0])
def test_the_compiled_slot_charges_and_pays_the_tables_energies(table_file, range_m, auv_depth_m):
    """One AUV charges node 0 and collects from node 1 at the same horizontal range: node 0
    gains the hand harvest of TL(70 kHz), node 1 pays the hand E_req of TL(50 kHz), both at
    the horizontal range and the AUV's depth (not the slant range)."""
    ch = with_table(table_file, auv_depth_m=auv_depth_m)
    nodes = [(500.0 - range_m / 2, 500.0), (500.0 + range_m / 2, 500.0)]
    net = SensorNetwork(
        nodes, NetworkConfig(node_initial_energy_j=1.0), AcousticsConfig(), channel=ch
    )
    links = serve(net, [[500.0, 500.0]], [1], wet=[0])
    half = range_m / 2
    assert links.distance_m[0].tolist() == pytest.approx([math.hypot(half, 100 - auv_depth_m)] * 2)
    assert links.uplink_ok.tolist() == [True]
    harvest = hand_harvest_j(known_tl_db(70.0, half, auv_depth_m))
    uplink = hand_uplink_j(known_tl_db(50.0, half, auv_depth_m))
    assert net.energy_j.tolist() == pytest.approx([1.0 + harvest, 1.0 - uplink], rel=1e-12)


def test_link_budget_mission_and_planners_read_the_same_table(table_file):
    ac = AcousticsConfig()
    link = acoustics.LinkBudget(ac, with_table(table_file))
    assert link.has_table and not acoustics.LinkBudget(ac, ChannelConfig()).has_table
    harvest, uplink = link.energies_j([[80.0, 640.0]], [[50.0], [30.0]], 100.0)
    wet_db, data_db = link.transmission_loss_db([[80.0, 640.0]], [[50.0], [30.0]], 100.0)
    for i, z in enumerate((50.0, 30.0)):
        for j, r in enumerate((80.0, 640.0)):
            assert harvest[i, j] == pytest.approx(hand_harvest_j(known_tl_db(70, r, z)), rel=1e-12)
            assert uplink[i, j] == pytest.approx(hand_uplink_j(known_tl_db(50, r, z)), rel=1e-12)
            assert wet_db[i, j] == pytest.approx(known_tl_db(70, r, z), abs=1e-9)
            assert data_db[i, j] == pytest.approx(known_tl_db(50, r, z), abs=1e-9)
    # the formula's entry point refuses a table rather than ignore it
    with pytest.raises(Exception, match="iout_link_pair_energies"):
        from iout_mj import native

        d = np.array([100.0])
        out = np.empty(1)
        native.call(
            native.lib.iout_link_energies,
            native.address(link.constants),
            native.address(d),
            1,
            native.address(out),
            native.address(out.copy()),
        )
    cfg = make_config(2, 7).replace(channel=with_table(table_file, auv_depths_m=(20.0, 60.0)))
    mission = Mission(cfg)
    mission.reset(np.random.RandomState(0))
    xy = np.array([[100.0, 200.0], [700.0, 300.0]])
    got_harvest, got_uplink = mission.link_energies_j(xy)
    horizontal = np.hypot(
        *(xy[:, None, :] - np.asarray(cfg.scenario.nodes_m)[None]).transpose(2, 0, 1)
    )
    for i, z in enumerate((20.0, 60.0)):
        np.testing.assert_allclose(
            got_uplink[i], [hand_uplink_j(known_tl_db(50, r, z)) for r in horizontal[i]], rtol=1e-12
        )
        np.testing.assert_allclose(
            got_harvest[i],
            [hand_harvest_j(known_tl_db(70, r, z)) for r in horizontal[i]],
            rtol=1e-12,
        )


def test_without_a_table_the_link_constants_are_the_papers(table_file):
    """No transmission_loss_file: the table fields of the compiled constants stay zero and the
    energies are the formula's at the slant range."""
    ac = AcousticsConfig()
    paper = acoustics.LinkBudget(ac).constants
    assert paper["tl_ranges"][0] == paper["tl_depths"][0] == 0
    assert not paper["tl_wet_db"].any()
    ch = ChannelConfig(features=("depth",))
    harvest, uplink = acoustics.LinkBudget(ac, ch).energies_j(300.0, 50.0, 100.0)
    slant = math.hypot(300.0, 50.0)
    assert uplink == pytest.approx(float(acoustics.uplink_energy_j(slant, ac)), rel=1e-12)
    assert harvest == pytest.approx(float(acoustics.harvest_energy_j(slant, ac)), rel=1e-12)


def realistic_with_table(path, n_auvs=2, n_nodes=7) -> Config:
    base = make_config(n_auvs, n_nodes, base=load_config(REALISTIC))
    channel = dataclasses.replace(base.channel, transmission_loss_file=str(path))
    return base.replace(channel=channel)


def test_a_kinematic_mission_flies_with_a_table_and_a_batch_of_one_is_the_single_env(
    table_file, rng
):
    cfg = realistic_with_table(table_file)
    assert cfg.channel.label.endswith("+tl-table")
    single = gym.make(ENV_ID, backend="kinematic", config=cfg)
    batch = KinematicVecEnv(1, config=cfg, seed=0)
    obs, _ = single.reset(seed=0)
    np.testing.assert_array_equal(batch.reset()[0], obs)
    plain = gym.make(
        ENV_ID, backend="kinematic", config=make_config(2, 7, base=load_config(REALISTIC))
    )
    plain.reset(seed=0)
    ends = differs = 0
    for _ in range(70):
        action = rng.integers(0, single.action_space.nvec)
        obs, reward, term, trunc, _ = single.step(action)
        b_obs, b_reward, _, b_infos = batch.step(action[None])
        p_obs, *_ = plain.step(action)
        differs += not np.array_equal(obs, p_obs)
        assert b_reward[0] == reward
        if term or trunc:
            ends += 1
            assert "metrics" in b_infos[0]
            obs, _ = single.reset()
            plain.reset()
        np.testing.assert_array_equal(b_obs[0], obs)
    assert ends >= 1 and differs > 0  # the table changes the links the observation shows


def test_config_file_paths_resolve_from_the_files_folder(tmp_path, table_file):
    folder = tmp_path / "configs"
    folder.mkdir()
    (folder / "site.yaml").write_text(
        "channel:\n  features: [depth]\n  transmission_loss_file: ../site.npz\n"
    )
    cfg = Config.load(folder / "site.yaml")
    assert cfg.channel.transmission_loss_file == str(tmp_path / "site.npz")
    saved = tmp_path / "run" / "config.yaml"  # a run's copy reads the same table
    saved.parent.mkdir()
    cfg.save(saved)
    assert Config.load(saved) == cfg
    assert acoustics.LinkBudget(cfg.acoustics, cfg.channel).has_table


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"features": ()}, r"features=\(\) is invalid: accepted 'depth' among them"),
        (
            {"absorption": "francois-garrison"},
            r"absorption='francois-garrison' is invalid: accepted 'thorp' with a",
        ),
        ({"transmission_loss_file": "site.csv"}, r"accepted a path to an .npz table"),
    ],
)
def test_channel_settings_a_table_needs(fields, message):
    with pytest.raises(ConfigError, match=message):
        ChannelConfig(**{"features": ("depth",), "transmission_loss_file": "site.npz", **fields})


@pytest.mark.parametrize(
    ("table", "channel", "message"),
    [
        (
            synthetic(frequencies=(50.0,)),
            {},
            r"acoustics.f_wet_khz is 70 kHz, not in the table: accepted a table holding both "
            r"link frequencies \(it holds \[50.0\] kHz\)",
        ),
        (
            synthetic(ranges=np.arange(1.0, link_bounds()["ranges"] + 2.0)),
            {},
            r"a table of 3 depths x 2049 ranges: accepted at most 128 depths, 2048 ranges",
        ),
        (
            synthetic(ranges=np.arange(1.0, 1501.0, 0.25)),
            {},
            r"a table of 3 depths x 6000 ranges: .* and 16384 depths x ranges",
        ),
        (
            synthetic(source=149.5),
            {},
            r"source \(a node\) lies at 149.5 m, for a seabed at 150 m; the channel's nodes "
            r"lie on seabeds at \[100.0\] m: accepted a table made for them",
        ),
        (
            synthetic(),
            {"auv_depths_m": (50.0, 95.0)},
            r"AUV depths \[95.0\] m lie outside the table's depths: accepted AUV depths from "
            r"10 to 90 m",
        ),
    ],
)
def test_a_table_the_link_budget_cannot_use_is_refused(tmp_path, table, channel, message):
    path = tmp_path / "bad.npz"
    save_table(table, path)
    with pytest.raises(TLTableError, match=message):
        acoustics.LinkBudget(AcousticsConfig(), with_table(path, **channel))


def test_a_table_short_of_the_areas_diagonal_or_missing_is_refused(tmp_path):
    path = tmp_path / "short.npz"
    save_table(synthetic(ranges=np.array([10.0, 500.0, 1000.0])), path)
    cfg = make_config(1, 7).replace(channel=with_table(path))
    with pytest.raises(
        TLTableError, match=r"reaches 1000 m, short of the area's diagonal \(1414.2 m\)"
    ):
        Mission(cfg)
    with pytest.raises(TLTableError, match=r"cannot read it .* accepted an .npz table"):
        acoustics.LinkBudget(AcousticsConfig(), with_table(tmp_path / "absent.npz"))


def run_cli(capsys, *args: str) -> str:
    assert cli.main(list(args)) == 0
    return capsys.readouterr().out


def test_link_budget_shows_the_tables_tl(tmp_path, table_file, capsys):
    cfg_path = tmp_path / "site.yaml"
    cfg_path.write_text("channel:\n  features: [depth]\n  transmission_loss_file: site.npz\n")
    rows = json.loads(
        run_cli(
            capsys, "link-budget", "--config", str(cfg_path), "--distance", "100", "700", "--json"
        )
    )["link"]
    assert [r["distance_m"] for r in rows] == [100.0, 700.0]
    for r in rows:
        assert r["auv_depth_m"] == 50.0
        assert r["tl_wet_db"] == pytest.approx(known_tl_db(70, r["distance_m"], 50.0))
        assert r["tl_data_db"] == pytest.approx(known_tl_db(50, r["distance_m"], 50.0))
        assert r["uplink_energy_j"] == pytest.approx(hand_uplink_j(r["tl_data_db"]), rel=1e-12)
        assert r["harvest_energy_j"] == pytest.approx(hand_harvest_j(r["tl_wet_db"]), rel=1e-12)
    text = run_cli(capsys, "link-budget", "--config", str(cfg_path), "--distance", "100")
    assert "TL 70 kHz" in text and "table site.npz" in text


def test_tl_table_command_names_the_extra_without_pelagic(tmp_path, capsys):
    if importlib.util.find_spec("pelagic") is not None:
        pytest.skip("pelagic is installed: the command computes the table")
    code = cli.main(["tl-table", "--out", str(tmp_path / "t.npz")])
    assert code != 0
    assert "pip install -e .[bellhop]" in capsys.readouterr().err
    assert not (tmp_path / "t.npz").exists()


SHIPPED = ROOT / "training/configs/env/realistic-channel-bellhop.yaml"
"""An overlay: the realistic channel's file, then this one."""


def test_the_shipped_bellhop_table_flies_a_mission():
    """The shipped realistic channel with BELLHOP's table: TL above the paper's practical
    spreading (k_s 1.5) and below spherical spreading, more at 70 kHz, and a mission runs."""
    cfg = make_config(2, 7, base=load_config([REALISTIC, SHIPPED]))
    link = acoustics.LinkBudget(cfg.acoustics, cfg.channel)
    ranges = np.array([100.0, 500.0, 1000.0])
    wet_db, data_db = link.transmission_loss_db(ranges, 50.0, 100.0)
    slant = np.hypot(ranges, 50.0)
    alpha = acoustics.thorp_absorption_db_per_km(50.0) * slant / 1000
    assert np.all(wet_db > data_db) and np.all(np.diff(data_db) > 0)
    assert np.all(15 * np.log10(slant) + alpha < data_db)
    assert np.all(data_db < 20 * np.log10(slant) + alpha)
    env = gym.make(ENV_ID, backend="kinematic", config=cfg)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(10):
        env.step(rng.integers(0, env.action_space.nvec))


@pytest.mark.slow
def test_bellhop_table_end_to_end(tmp_path, capsys):
    """tl-table on the shipped realistic channel makes the shipped table; a mission flies it."""
    if importlib.util.find_spec("pelagic") is None:
        pytest.skip("pelagic (BELLHOP) is an optional extra: pip install -e .[bellhop]")
    out = tmp_path / "realistic.npz"
    run_cli(capsys, "tl-table", "--config", str(REALISTIC), "--out", str(out))
    made, shipped = load_table(out), load_table(SHIPPED.with_suffix(".npz"))
    for name in ("frequency_khz", "depth_m", "range_m", "tl_db"):
        np.testing.assert_allclose(getattr(made, name), getattr(shipped, name), atol=1e-9)
    env = gym.make(ENV_ID, backend="kinematic", config=realistic_with_table(out))
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(10):
        env.step(rng.integers(0, env.action_space.nvec))
