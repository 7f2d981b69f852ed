"""Sensor-node rules: AoI growth, cap, K_reset, energy causality, Jain (the compiled
`iout_serve` on a `SensorNetwork`, one slot at a time)."""

import ctypes
from typing import NamedTuple

import numpy as np
import pytest

from iout_mj import native
from iout_mj.config import AcousticsConfig, NetworkConfig
from iout_mj.world import acoustics
from iout_mj.world.network import SensorNetwork

NODES = [(100.0, 100.0), (900.0, 900.0)]
NEAR = np.array([[100.0, 150.0]])  # 50 m from node 0, far from node 1


def make(k_reset=3, aoi_max=50.0, e0=0.1):
    return SensorNetwork(
        NODES,
        NetworkConfig(k_reset=k_reset, aoi_max=aoi_max, node_initial_energy_j=e0),
        AcousticsConfig(),
    )


class Outcome(NamedTuple):
    distance_m: np.ndarray
    uplink_ok: np.ndarray
    uplink_req_j: np.ndarray
    uplink_stored_j: np.ndarray
    harvested_j: np.ndarray
    delivered: np.ndarray


def serve(net, xy, wet, data, active, env=0):
    """One slot of env `env` of `net` by the compiled rules; what it did."""
    xy = np.ascontiguousarray(xy, dtype=float)
    n, k = len(xy), net.n_nodes
    out = Outcome(
        np.zeros((n, k)),
        np.zeros(n, bool),
        np.zeros(n),
        np.zeros(n),
        np.zeros(k),
        np.zeros(k, bool),
    )
    args = [np.ascontiguousarray(a, dtype=t) for a, t in ((wet, np.int64), (data, np.int64))]
    native.call(
        native.lib.iout_serve,
        ctypes.addressof(net._struct),
        env,
        len(net._arrays.aoi),
        n,
        k,
        native.address(net.link.constants),
        net.cfg.k_reset,
        net.cfg.aoi_max,
        native.address(xy),
        *(native.address(a) for a in args),
        1,
        native.address(np.ascontiguousarray(active, dtype=bool)),
        *(native.address(x) for x in out),
    )
    return out


def step(net, data_node, wet_node=0, xy=NEAR, active=True):
    return serve(net, xy, [wet_node], [data_node], [active])


def test_aoi_grows_by_one_and_caps():
    net = make(aoi_max=5.0)
    for expected in (2, 3, 4, 5, 5, 5):
        step(net, data_node=1, active=False)  # inactive AUV: nothing delivered
        assert net.aoi[0] == expected


def test_reset_after_exactly_k_reset_deliveries():
    net = make(k_reset=3)
    aoi = []
    for _ in range(4):
        out = step(net, data_node=0)
        assert out.delivered[0]
        aoi.append(net.aoi[0])
    # deliveries 1 and 2 only age the node; the third resets it to 1; the counter restarts
    assert aoi == [2.0, 3.0, 1.0, 2.0]
    assert net.service_count[0] == 1
    assert net.deliveries[0] == 4


def test_failed_deliveries_do_not_reset_or_count():
    net = make(e0=0.0)  # no stored energy: the node cannot transmit
    far = np.array([[900.0, 100.0]])  # and AET from 800 m harvests almost nothing
    for _ in range(5):
        out = step(net, data_node=0, wet_node=1, xy=far)
        assert not out.delivered[0]
        assert not out.uplink_ok[0]
    assert net.aoi[0] == 6.0
    assert net.deliveries[0] == 0
    assert net.service_count[0] == 0


def test_energy_causality_pays_e_req_from_start_of_slot_energy():
    cfg = AcousticsConfig()
    d = 50.0
    req = float(acoustics.uplink_energy_j(d, cfg))
    harvest = float(acoustics.harvest_energy_j(d, cfg))
    net = make(e0=req * 0.5)  # not enough at the start of the slot
    out = step(net, data_node=0, wet_node=0)
    assert not out.delivered[0]  # this slot's harvest does not count for this slot's uplink
    assert net.energy_j[0] == pytest.approx(req * 0.5 + harvest)
    out = step(net, data_node=0, wet_node=1)  # now it has enough; charge the other node
    assert out.delivered[0]
    assert net.energy_j[0] == pytest.approx(req * 0.5 + harvest - req)


def test_two_auvs_on_one_node_count_one_delivery_at_the_nearest_cost():
    net = make()
    xy = np.array([[100.0, 150.0], [100.0, 400.0]])
    e0 = net.energy_j[0]
    out = serve(net, xy, [1, 1], [0, 0], [True, True])
    assert out.uplink_ok.tolist() == [True, True]
    assert net.deliveries[0] == 1
    spent = e0 + out.harvested_j[0] - net.energy_j[0]
    assert spent == pytest.approx(acoustics.uplink_energy_j(50.0, AcousticsConfig()))


def test_harvest_from_two_auvs_adds_up():
    net = make(e0=0.0)
    xy = np.array([[100.0, 150.0], [100.0, 150.0]])
    out = serve(net, xy, [0, 0], [1, 1], [True, True])
    single = acoustics.harvest_energy_j(50.0, AcousticsConfig())
    assert out.harvested_j[0] == pytest.approx(2 * single)


def test_delivered_bits():
    net = make()
    step(net, data_node=0)
    assert net.delivered_bits == 12_000 * 25


@pytest.mark.parametrize(
    ("counts", "expected"),
    [
        ([3, 3, 3, 3], 1.0),
        ([4, 0, 0, 0], 0.25),  # 16 / (4 * 16)
        ([1, 2, 3], 36 / (3 * 14)),  # 0.857142...
        ([0, 0, 0], 0.0),  # nothing delivered: defined as 0
    ],
)
def test_jain(counts, expected):
    net = SensorNetwork([(0.0, 0.0)] * len(counts), NetworkConfig(), AcousticsConfig())
    net.deliveries[...] = counts
    net.summarise()
    assert net.jain == pytest.approx(expected)


def test_batched_network_steps_each_row_like_a_single_network():
    single = [make(), make()]
    batch = SensorNetwork(
        NODES,
        NetworkConfig(k_reset=3, aoi_max=50.0, node_initial_energy_j=0.1),
        AcousticsConfig(),
        batch=(2,),
    )
    xy = np.array([[[100.0, 150.0]], [[880.0, 900.0]]])  # row 0 near node 0, row 1 near node 1
    for t in range(5):
        data, wet = np.array([[0], [t % 2]]), np.array([[1], [1]])
        for r, net in enumerate(single):
            out = serve(batch, xy[r], wet[r], data[r], [True], env=r)
            o = serve(net, xy[r], wet[r], data[r], [True])
            np.testing.assert_allclose(out.uplink_req_j, o.uplink_req_j)
            np.testing.assert_array_equal(out.uplink_ok, o.uplink_ok)
            np.testing.assert_allclose(batch.energy_j[r], net.energy_j)
            np.testing.assert_array_equal(batch.aoi[r], net.aoi)
            np.testing.assert_array_equal(batch.jain[r], net.jain)
    assert batch.deliveries.sum() > 0


@pytest.mark.parametrize(
    ("env", "wet", "data", "message"),
    [
        (2, 0, 0, r"env 2 of 2"),
        (-1, 0, 0, r"env -1 of 2"),
        (0, 2, 0, r"names nodes 2 and 0; accepted 0 to 1"),
        (0, 0, -1, r"names nodes 0 and -1; accepted 0 to 1"),
    ],
)
def test_serve_refuses_an_env_or_node_out_of_range(env, wet, data, message):
    net = SensorNetwork(NODES, NetworkConfig(), AcousticsConfig(), batch=(2,))
    before = net.energy_j.copy()
    with pytest.raises(native.NativeError, match=message):
        serve(net, NEAR, [wet], [data], [True], env=env)
    np.testing.assert_array_equal(net.energy_j, before)  # refused before anything changed
