"""The compiled token observation (`mission/tokens.c`) against the features computed again
here in numpy from the mission's state, for N = 1 to 4, K = 3 to 30, single envs and batches,
mid-episode; and its checks."""

import gymnasium as gym
import numpy as np
import pytest

from iout_mj.envs import ENV_ID
from iout_mj.envs.batch import MissionBatch
from iout_mj.mission.tokens import (
    ETA_CRUISE_MPS,
    GLOBAL_FEATURES,
    K_MAX,
    auv_features,
    node_features,
    token_size,
)
from iout_mj.native import NativeError


def _bearing(delta_m, heading_rad):
    rel = np.arctan2(delta_m[..., 1], delta_m[..., 0]) - heading_rad
    return np.stack([np.cos(rel), np.sin(rel)], axis=-1)


def numpy_tokens(mission, k_max=K_MAX):
    """The token observation from the state, written out feature by feature (batched)."""
    s, net, cfg, p = mission.state, mission.network, mission.cfg, mission.params[0]
    n, k, batch = mission.n_auvs, mission.n_nodes, mission.batch
    area, diag = np.asarray(cfg.scenario.area_m, float), 1 / float(p["inv_diag_per_m"])
    left = 1 - s.slot / cfg.scenario.horizon_slots
    aoi = net.aoi / cfg.network.aoi_max
    glob = np.stack(np.broadcast_arrays(left, k / k_max, aoi.mean(-1)), -1)
    hsp = s.heading_sp
    v_max = cfg.motion.v_max_mps
    eta = s.dock_dist_m / (ETA_CRUISE_MPS * cfg.scenario.slot_s) / cfg.scenario.horizon_slots
    auv = [
        s.positions_m / area,
        np.stack([np.cos(hsp), np.sin(hsp)], -1),
        np.minimum(s.speeds_mps / v_max, 2.0)[..., None],
        (s.speed_sp / v_max)[..., None],
        s.docked[..., None].astype(float),
        (s.dock_dist_m / diag)[..., None],
        _bearing(mission.dock_m - s.positions_m, hsp),
        np.clip(left[..., None] - eta, -1, 1)[..., None],
    ]
    others = []
    for i in range(n):
        row = []
        for j in range(n):
            if j != i:
                d = s.positions_m[..., j, :] - s.positions_m[..., i, :]
                row.append(np.linalg.norm(d, axis=-1)[..., None] / diag)
                row.append(_bearing(d, hsp[..., i]))
        others.append(np.concatenate(row, -1) if row else np.zeros((*batch, 0)))
    auv.append(np.stack(others, -2))
    auv_tokens = np.concatenate(auv, -1).reshape(*batch, -1)
    _, need = net.link.energies_j(s.distance_m)
    afford = np.clip(np.log10(np.maximum(net.energy_j[..., None, :], 1e-12) / need) / 3, -1, 2)
    delta = net.nodes_m[..., None, :, :] - s.positions_m[..., :, None, :]
    links = np.concatenate(
        [(s.distance_m / diag)[..., None], _bearing(delta, hsp[..., None]), afford[..., None]], -1
    )  # (*b, N, K, 4)
    energy = np.minimum(np.log10(1 + net.energy_j / 1e-3) / 5, 2.0)
    nodes = np.concatenate(
        [
            net.nodes_m / area - 0.5,
            aoi[..., None],
            (net.service_count / cfg.network.k_reset)[..., None],
            energy[..., None],
            np.moveaxis(links, -3, -2).reshape(*batch, k, -1),
        ],
        -1,
    )
    padded = np.zeros((*batch, k_max, nodes.shape[-1]))
    padded[..., :k, :] = nodes
    mask = (np.arange(k_max) < k).astype(float) * np.ones((*batch, 1))
    return np.concatenate([glob, auv_tokens, padded.reshape(*batch, -1), mask], -1)


@pytest.mark.parametrize("n, k", [(1, 3), (2, 11), (3, 20), (4, 30), (2, 7)])
def test_compiled_tokens_equal_the_features_written_out_in_numpy(n, k):
    batch = MissionBatch(4, "kinematic", n, k, "random", seed=n * 100 + k, observation="tokens")
    batch.restart()
    rng = np.random.default_rng(k)
    nvec = np.tile([8, 3, k, k], n)
    for t in range(40):  # mid-episode states: docked AUVs, served nodes, varied energy
        step = batch.step(rng.integers(0, nvec, size=(4, len(nvec))))
        if t % 13 == 0:
            expected = numpy_tokens(batch.mission)
            assert step.obs.shape == (4, token_size(n)) and step.obs.dtype == np.float32
            np.testing.assert_allclose(step.obs, expected, rtol=2e-6, atol=2e-6)
    assert GLOBAL_FEATURES + n * auv_features(n) + K_MAX * (node_features(n) + 1) == token_size(n)


def test_single_env_tokens_and_a_smaller_k_max():
    env = gym.make(ENV_ID, n_auvs=2, n_nodes=9, backend="kinematic", layout="random")
    env.reset(seed=3)
    for _ in range(10):
        env.step(env.action_space.sample())
    mission = env.unwrapped.mission
    for k_max in (9, 12):
        obs = mission.observe_tokens(k_max)
        assert obs.shape == (token_size(2, k_max),)
        np.testing.assert_allclose(obs, numpy_tokens(mission, k_max), rtol=2e-6, atol=2e-6)
    with pytest.raises(NativeError, match="k_max 8; accepted K = 9"):
        mission.observe_tokens(8)
