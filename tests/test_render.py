"""Headless rendering (EGL on Mesa's llvmpipe here)."""

import os
import subprocess
import sys

import gymnasium as gym
import imageio_ffmpeg
import numpy as np
import pytest

from iout_mj.agents.policies import load_policy
from iout_mj.backends.mujoco import overlay
from iout_mj.backends.mujoco.render import Z_NODE_M
from iout_mj.envs import ENV_ID
from iout_mj.experiments.mission import run_mission
from iout_mj.scenarios import make_config, resolve

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
    out = cli(
        *("render", "--policy", "greedy", "--slots", "2", "--width", "320", "--height", "180"),
        *("--fps", "10", "--out", tmp_path),
    )
    assert "17 frames" in out.stdout
    assert (tmp_path / "mission.mp4").stat().st_size > 1000
    assert (tmp_path / "mission.png").exists()
    bad = cli("render", "--out", tmp_path / "clip.mp4", check=False)
    assert bad.returncode == 2 and "accepted a folder" in bad.stderr


def test_frame_panel_labels_and_chase_camera_at_960x540():
    """N = 4: AUV 1 docks first; the chase camera moves on to an AUV under way, the panel
    (beside the map, text on it) says where AUV 1 docked, node labels sit on the nodes."""
    env = gym.make(
        ENV_ID,
        backend="kinematic",
        config=resolve(None, 4, 9),
        render_mode="rgb_array",
        width=960,
        height=540,
    )
    obs, _ = env.reset(seed=0)
    policy = load_policy("tour-scheduler", env, 0)
    policy.reset(0)
    env.render()
    mission, renderer = env.unwrapped.mission, env.unwrapped.renderer
    while not mission.state.docked[0]:
        obs, *_ = env.step(policy(env, obs))
    assert not mission.state.docked.all()
    docked_slot = int(mission.state.slot)
    assert renderer.docked_at[0] == docked_slot
    assert renderer.chased > 0 and not mission.state.docked[renderer.chased]
    frame = env.render()
    lay = renderer.layout
    panel = frame[lay.chase_h :, lay.map_w :].reshape(-1, 3)
    background = np.all(panel == overlay.PANEL_RGB, axis=1).mean()
    text = np.all(panel > 200, axis=1).mean()
    assert background > 0.6 and text > 0.01  # a dark panel with light text on it
    chase = frame[: lay.chase_h, lay.map_w :].reshape(-1, 3)
    assert np.all(chase == overlay.PANEL_RGB, axis=1).mean() < 0.05  # a rendered view
    state = renderer._panel_state()
    assert state.aoi_so_far == mission.metrics()["mean_aoi"]
    lines = overlay.Panel(lay.side_w, lay.panel_h, state).lines(state)
    assert f"AUV 1  {state.energy_kj[0]:.0f} kJ,  docked at slot {docked_slot}" in lines
    cam, d = renderer._top_cam, renderer._view_data
    nodes = np.column_stack([mission.network.nodes_m, np.full(mission.n_nodes, Z_NODE_M)])
    px = overlay.project(
        nodes, d.cam_xpos[cam], d.cam_xmat[cam], renderer.model.cam_fovy[cam], 540, 540
    )
    centres = frame[px[:, 1].round().astype(int), px[:, 0].round().astype(int)].astype(int)
    assert np.all(centres[:, 1] > 200) and np.all(centres[:, 1] > centres[:, [0, 2]].max(1))
    env.close()
