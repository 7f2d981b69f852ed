"""Headless rendering (EGL on Mesa's llvmpipe here)."""

import os
import subprocess
import sys

import gymnasium as gym
import imageio_ffmpeg
import numpy as np
import pytest

from iout_mj.experiments.mission import run_mission
from iout_mj.scenarios import make_config

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("backend", ["mujoco", "kinematic"])
def test_short_clip(tmp_path, backend):
    summary = run_mission(
        policy="planner",
        config=make_config(2, 7),
        backend=backend,
        out=tmp_path,
        slots=3,
        width=320,
        height=160,
        fps=10,
    )
    reader = imageio_ffmpeg.read_frames(str(tmp_path / "mission.mp4"))
    meta = next(reader)
    w, h = meta["size"]
    video = np.stack([np.frombuffer(f, np.uint8).reshape(h, w, 3) for f in reader])
    assert video.shape == (1 + 3 * 8, 160, 320, 3)  # the start, then 8 frames per slot
    assert summary["video_frames"] == 25
    assert (tmp_path / "mission.png").exists()
    diffs = [
        np.abs(video[i + 1].astype(int) - video[i].astype(int)).mean()
        for i in range(len(video) - 1)
    ]
    assert min(diffs) > 0  # every frame differs from the one before
    # AUV 2's magenta marker and trail move in the top view (the left 160 px)
    top = video[:, :, :160].astype(int)
    marker = (top[..., 0] > 180) & (top[..., 1] < 130) & (top[..., 2] > 130)
    first, last = np.argwhere(marker[0]), np.argwhere(marker[-1])
    assert len(first) and len(last)
    assert np.abs(first.mean(axis=0) - last.mean(axis=0)).max() > 1.0


def test_render_mode_rgb_array():
    env = gym.make("iout_mj/MultiAUV-v0", render_mode="rgb_array", width=200, height=120)
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (120, 200, 3) and frame.dtype == np.uint8
    env.close()


@pytest.mark.parametrize("backend", ["mujoco", "kinematic"])
def test_render_mode_rgb_array_list_gives_every_frame_since_the_last_call(backend):
    env = gym.make(
        "iout_mj/MultiAUV-v0", backend=backend, render_mode="rgb_array_list", width=96, height=64
    )
    env.reset(seed=0)
    env.step(env.action_space.sample())
    frames = env.render()
    assert len(frames) == 1 + 8 and frames[0].shape == (64, 96, 3)  # the start, one slot
    assert env.render() == []  # taken
    env.step(env.action_space.sample())
    assert len(env.render()) == 8
    env.close()


def test_missing_gl_library_gives_the_documented_message():
    code = (
        "import ctypes.util, os\n"
        "ctypes.util.find_library = lambda name: None\n"  # as on a machine without Mesa
        "import iout_mj, mujoco\n"
        "print(os.environ['MUJOCO_GL'], '|', iout_mj.GL_NOTE)\n"
        "from iout_mj.backends.mujoco.render import make_renderer, RenderError\n"
        "try:\n"
        "    make_renderer(mujoco.MjModel.from_xml_string('<mujoco/>'), 8, 8)\n"
        "except RenderError as e:\n"
        "    print('ERROR', e)\n"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")}
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True
    ).stdout
    assert out.startswith("disable | MUJOCO_GL=egl: neither libEGL nor libOSMesa")
    assert "ERROR offscreen rendering failed" in out and "libegl-mesa0" in out


def test_render_command(tmp_path, cli):
    clip = tmp_path / "clip.mp4"
    out = cli(
        *("render", "--policy", "greedy", "--slots", "2", "--width", "320", "--height", "180"),
        *("--fps", "10", "--out", clip),
    )
    assert "17 frames" in out.stdout
    assert clip.stat().st_size > 1000 and clip.with_suffix(".png").exists()
    bad = cli("render", "--out", tmp_path / "clip.gif", check=False)
    assert bad.returncode == 2 and "accepted a path ending in .mp4" in bad.stderr
