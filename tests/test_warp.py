"""MuJoCo Warp backend against the C backend on Warp's CPU device, and on the GPU where Warp
sees one (skipped elsewhere; CI has none): same start states and actions, N = 2, K = 7, a few
worlds, two slots (slow: Warp compiles its kernels on first use, ~30 s, cached afterwards)."""

import numpy as np
import pytest

pytest.importorskip("mujoco_warp")

from iout_mj.backends.mujoco.warp_stepper import WarpStepper, default_device
from iout_mj.envs.batch import MissionBatch

CONFIG = {"physics": {"current_jitter_mps": 0.5}}
WORLDS = 8
DEVICES = ["cpu", "cuda"]
"""On "cuda" the substep loop runs as a captured CUDA graph."""


def _pair(device: str) -> tuple[MissionBatch, MissionBatch]:
    if device == "cuda" and default_device() != "cuda":
        pytest.skip("Warp sees no GPU here")
    c = MissionBatch(WORLDS, "mujoco", 2, 7, "random", CONFIG, seed=11)
    w = MissionBatch(WORLDS, "mujoco", 2, 7, "random", CONFIG, seed=11)
    w.stepper = WarpStepper(device=device)
    c.restart()
    w.restart()
    return c, w


POSITION_TOLERANCE_M = (2e-4, 5e-3)
"""After one and two slots. MuJoCo Warp computes in float32: one slot (500 substeps) stays
within 1e-4 m, the second drifts to ~1.4e-3 m where the servos saturate (README, "warp")."""
ENERGY_TOLERANCE = (2e-4, 1e-2)
"""Relative, per slot: C MuJoCo itself moves the slot's energy by 5e-4 under a 2e-7 rad nudge."""


@pytest.mark.slow
@pytest.mark.parametrize("device", DEVICES)
def test_warp_matches_c_mujoco_over_two_slots(device: str):
    c, w = _pair(device)
    rng = np.random.RandomState(1)
    for slot in range(2):
        a = np.stack(
            [
                np.concatenate([[rng.randint(11), rng.randint(7), rng.randint(7), 1] for _ in "ab"])
                for _ in range(WORLDS)
            ]
        )
        sc, sw = c.step(a), w.step(a)
        qc = np.stack([p.data.qpos for p in c.physics])
        qw = np.stack([p.data.qpos for p in w.physics])
        xy = c.physics[0]._qxy
        assert np.abs(qc[:, xy] - qw[:, xy]).max() < POSITION_TOLERANCE_M[slot]
        energy = [np.stack([p.meter.read_j() for p in b.physics]) for b in (c, w)]
        np.testing.assert_allclose(energy[1], energy[0], rtol=ENERGY_TOLERANCE[slot])
        path_c = np.stack([p.substep_qpos for p in c.physics])
        path_w = np.stack([p.substep_qpos for p in w.physics])
        assert path_w.shape == path_c.shape
        assert np.abs(path_c - path_w).max() < POSITION_TOLERANCE_M[slot]
        np.testing.assert_allclose(sw.rewards, sc.rewards, atol=1e-2)
        np.testing.assert_array_equal(sw.terminated, sc.terminated)
    c.close()
    w.close()


@pytest.mark.slow
@pytest.mark.parametrize("device", DEVICES)
def test_warp_flags_a_diverged_world_as_the_c_backend_does(device: str):
    c, w = _pair(device)
    for b in (c, w):
        b.physics[1].data.qvel[:] = 1e30  # world 1 blows up
    a = np.tile([5, 3, 0, 1, 5, 3, 2, 3], (WORLDS, 1))
    failed = [b.move(a)[1] for b in (c, w)]
    np.testing.assert_array_equal(failed[0], np.arange(WORLDS) == 1)
    np.testing.assert_array_equal(failed[1], failed[0])


def test_warp_backend_is_refused_clearly_without_mujoco_warp(monkeypatch):
    import builtins

    real = builtins.__import__

    def no_warp(name, *args, **kwargs):
        if name in ("warp", "mujoco_warp"):
            raise ImportError(f"No module named {name!r}")
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_warp)
    with pytest.raises(ImportError, match=r"iout-mj\[gpu\]"):
        WarpStepper()
