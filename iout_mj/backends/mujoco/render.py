"""Offscreen mission rendering (EGL, OSMesa fallback): top-down and chase views, trails, links,
node state and a text overlay; several frames per slot from the physics substeps.

Built from a model of the scene and a `Mission`: the renderer reads the mission state, never
the env. Nothing renders unless a frame is asked for.
"""

from __future__ import annotations

import itertools
import os

import mujoco
import numpy as np
from numpy.typing import NDArray
from PIL import Image, ImageDraw, ImageFont

import iout_mj
from iout_mj import palette
from iout_mj.backends.mujoco import names, vehicle
from iout_mj.backends.mujoco.physics import AUVPhysics, joint_addresses
from iout_mj.errors import IoutError
from iout_mj.mission import Mission
from iout_mj.mission.observation import node_energy_level
from iout_mj.types import FloatArray
from iout_mj.world.geometry import wrap_angle

TRAIL_POINTS = 400
MARKER_LENGTH_M = 40.0
LINK_WIDTH_PX = 3.0


class RenderError(IoutError, RuntimeError):
    """No offscreen OpenGL backend works on this machine."""


def make_renderer(model: mujoco.MjModel, height: int, width: int) -> mujoco.Renderer:
    """A mujoco.Renderer on the backend `iout_mj` chose at import (EGL, else OSMesa)."""
    backend = os.environ.get("MUJOCO_GL", "")
    try:
        return mujoco.Renderer(model, height, width, max_geom=20000)
    except Exception as exc:
        note = f" ({iout_mj.GL_NOTE})" if iout_mj.GL_NOTE else ""
        raise RenderError(
            f"offscreen rendering failed with MUJOCO_GL={backend!r}{note}: "
            f"{type(exc).__name__}: {exc}. Headless rendering needs Mesa's EGL (Debian: "
            "libegl-mesa0 libegl1) or OSMesa (libosmesa6); set MUJOCO_GL=egl or osmesa."
        ) from exc


class MissionRenderer:
    """Frames of a mission in a MuJoCo model of its scene, at `width` x `height`.

    The frame is the top-down view of the whole area beside a chase view of AUV 0
    (when `width` > `height`), with an overlay of time, mean AoI, Jain, data and energy.
    With `physics` (the MuJoCo backend) the frames of a slot come from its substeps; without
    (the kinematic backend) the vehicles are placed along straight lines. One class (over the
    house's ~150 lines): poses, trails, decorations and overlay share the two views' scenes.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        mission: Mission,
        width: int,
        height: int,
        physics: AUVPhysics | None = None,
        frames_per_slot: int = 8,
    ):
        self.model, self.mission, self.cfg = model, mission, mission.cfg
        self.frames_per_slot = frames_per_slot
        self._physics = physics
        self.data = physics.data.ptr if physics is not None else mujoco.MjData(model)
        self._view_data = mujoco.MjData(self.model)
        self.width, self.height = width, height
        self.top_size = min(width, height)
        chase_w = width - self.top_size
        if chase_w < 64:  # too narrow for a chase view: the top view takes the whole frame
            self.top_size, chase_w = width, 0
        self.top = make_renderer(self.model, height, self.top_size)
        self.chase = make_renderer(self.model, height, chase_w) if chase_w else None
        self._qx, self._qy, self._qyaw = joint_addresses(self.model, self.mission.n_auvs)
        self._nodes = [model.body(names.node_name(k)).id for k in range(mission.n_nodes)]
        self._chase_cam = names.auv_prefix(0) + names.CHASE_CAMERA
        self._font = ImageFont.load_default()
        self.reset()

    def reset(self) -> None:
        """Start a new episode: clear trails and frames, place this episode's node markers."""
        self.model.body_pos[self._nodes, :2] = self.mission.network.nodes_m
        self.trails: list[list[FloatArray]] = [[] for _ in range(self.mission.n_auvs)]
        self._slot_start_pose = self._pose_now()
        self._pending: list[NDArray[np.uint8]] = []

    # ------------------------------------------------------------------ poses
    def _pose_now(self) -> tuple[FloatArray, FloatArray]:
        m = self.mission
        return m.state.positions_m.copy(), m.state.headings_rad.copy()

    def _substep_poses(self) -> list[tuple[FloatArray, FloatArray]]:
        """Poses for the frames of the slot that just ended."""
        k = self.frames_per_slot
        if self._physics is not None:
            q = self._physics.substep_qpos
            idx = np.linspace(0, len(q) - 1, k + 1)[1:].round().astype(int)
            return [
                (np.stack([q[i, self._qx], q[i, self._qy]], axis=1), np.asarray(q[i, self._qyaw]))
                for i in idx
            ]
        (p0, h0), (p1, h1) = self._slot_start_pose, self._pose_now()
        dh = wrap_angle(h1 - h0)
        return [(p0 + (p1 - p0) * f, h0 + dh * f) for f in np.arange(1, k + 1) / k]

    def _place(self, xy: FloatArray, yaw: FloatArray) -> mujoco.MjData:
        d = self._view_data
        d.qpos[:] = self.data.qpos
        d.qpos[self._qx], d.qpos[self._qy], d.qpos[self._qyaw] = xy[:, 0], xy[:, 1], yaw
        mujoco.mj_kinematics(self.model, d)
        mujoco.mj_camlight(self.model, d)
        return d

    # ------------------------------------------------------------------ frames
    def record_slot(self, keep_frames: bool = True) -> None:
        """Extend the trails by the slot that just ended (call after each env step) and, with
        `keep_frames`, render its frames for `take_frames`."""
        for xy, yaw in self._substep_poses():
            for i in range(self.mission.n_auvs):
                self.trails[i].append(xy[i].copy())
            if keep_frames:
                self._pending.append(self._compose(xy, yaw))
        self._slot_start_pose = self._pose_now()

    def record_frame(self) -> None:
        """Keep the current frame (the first frame of an episode)."""
        self._pending.append(self.frame())

    def take_frames(self) -> list[NDArray[np.uint8]]:
        """Frames rendered since the last call."""
        frames, self._pending = self._pending, []
        return frames

    def frame(self) -> NDArray[np.uint8]:
        """The current frame."""
        xy, yaw = self._pose_now()
        return self._compose(xy, yaw)

    def _compose(self, xy: FloatArray, yaw: FloatArray) -> NDArray[np.uint8]:
        d = self._place(xy, yaw)
        self.top.update_scene(d, camera=names.TOP_CAMERA)
        self._decorate(self.top.scene, xy, yaw, top=True)
        views = [self.top.render()]
        if self.chase is not None:
            self.chase.update_scene(d, camera=self._chase_cam)
            self._decorate(self.chase.scene, xy, yaw, top=False)
            views.append(self.chase.render())
        img = np.concatenate(views, axis=1)
        return self._overlay(img)

    # ------------------------------------------------------------------ decorations
    def _add(self, scene: mujoco.MjvScene) -> mujoco.MjvGeom | None:
        if scene.ngeom >= scene.maxgeom:
            return None
        g = scene.geoms[scene.ngeom]
        scene.ngeom += 1
        return g

    def _line(
        self,
        scene: mujoco.MjvScene,
        a: FloatArray,
        b: FloatArray,
        rgba: FloatArray,
        width: float,
    ) -> None:
        g = self._add(scene)
        if g is None:
            return
        mujoco.mjv_initGeom(
            g,
            mujoco.mjtGeom.mjGEOM_LINE,
            np.zeros(3),
            np.zeros(3),
            np.eye(3).ravel(),
            rgba.astype(np.float32),
        )
        mujoco.mjv_connector(g, mujoco.mjtGeom.mjGEOM_LINE, width, a, b)

    def _decorate(self, scene: mujoco.MjvScene, xy: FloatArray, yaw: FloatArray, top: bool) -> None:
        mission, net = self.mission, self.mission.network
        z_auv = vehicle.AUV_DEPTH_M
        z_bed = vehicle.SEABED_DEPTH_M + 4.5
        # Nodes: colour = AoI, size = stored energy (log scale).
        radius = vehicle.NODE_RADIUS_M * (0.8 + 1.75 * node_energy_level(net.energy_j))
        colors = palette.aoi_rgba(net.aoi / self.cfg.network.aoi_max)
        for k, (x, y) in enumerate(net.nodes_m):
            g = self._add(scene)
            if g is None:
                break
            mujoco.mjv_initGeom(
                g,
                mujoco.mjtGeom.mjGEOM_CYLINDER,
                np.array([radius[k], radius[k], 1.5]),
                np.array([x, y, z_bed]),
                np.eye(3).ravel(),
                colors[k].astype(np.float32),
            )
        # Links of the slot being shown: AET (orange) and uplink (cyan, grey if it failed).
        log, slot = mission.log, int(mission.state.slot)
        if slot > 0:
            aet, up = log.aet_nodes[slot - 1], log.uplink_nodes[slot - 1]
            ok = log.uplink_ok[slot - 1]
            for i in range(mission.n_auvs):
                if mission.state.docked[i] and slot > 1:
                    continue
                p = np.array([xy[i, 0], xy[i, 1], z_auv])
                q_aet = np.array([*net.nodes_m[aet[i]], z_bed])
                q_up = np.array([*net.nodes_m[up[i]], z_bed + 1])
                self._line(scene, p, q_aet, palette.AET_RGBA, LINK_WIDTH_PX)
                self._line(
                    scene,
                    p + np.array([0.0, 0.0, 1.0]),
                    q_up,
                    palette.UPLINK_RGBA if ok[i] else palette.FAILED_RGBA,
                    LINK_WIDTH_PX,
                )
        # Trails and (top view) large heading markers, since a 3 m hull is a few pixels there.
        for i in range(mission.n_auvs):
            trail = self.trails[i][-TRAIL_POINTS:]
            step = max(1, len(trail) // 200)
            pts = trail[::step] + ([trail[-1]] if trail else [])
            color = palette.AUV_RGBA[i % len(palette.AUV_RGBA)]
            for a, b in itertools.pairwise(pts):
                self._line(scene, np.array([*a, z_auv]), np.array([*b, z_auv]), color, 2.0)
            if top:
                g = self._add(scene)
                if g is None:
                    break
                c, s = np.cos(yaw[i]), np.sin(yaw[i])
                mat = np.array([[0, -s, c], [0, c, s], [-1, 0, 0]], dtype=float)
                mujoco.mjv_initGeom(
                    g,
                    mujoco.mjtGeom.mjGEOM_ARROW,
                    np.array([12.0, 12.0, MARKER_LENGTH_M]),
                    np.array([xy[i, 0], xy[i, 1], z_auv]),
                    mat.ravel(),
                    color.astype(np.float32),
                )

    def _overlay(self, img: NDArray[np.uint8]) -> NDArray[np.uint8]:
        """Text on the chase view (or on the top view when there is no chase view)."""
        m = self.mission
        slot_s = self.cfg.scenario.slot_s
        energy_kj = ", ".join(f"{e / 1e3:.0f}" for e in m.state.propulsion_energy_j)
        slot, horizon = m.state.slot, self.cfg.scenario.horizon_slots
        lines = [
            f"t = {slot * slot_s:5.0f} s  (slot {slot}/{horizon})",
            f"mean AoI {m.network.mean_aoi:5.1f}   Jain {m.network.jain:4.2f}",
            f"data {m.network.delivered_bits / 1e6:6.1f} Mbit",
            f"energy/AUV {energy_kj} kJ",
            "docked " + " ".join("Y" if d else "-" for d in m.state.docked),
            "orange AET, cyan uplink (grey: failed)",
            "node colour: AoI, size: stored energy",
        ]
        x0 = self.top_size if self.chase is not None else 0
        image = Image.fromarray(img)
        draw = ImageDraw.Draw(image)
        pad, line_h = 4, 12
        width = min(img.shape[1] - x0, 240)
        draw.rectangle([x0, 0, x0 + width, line_h * len(lines) + 2 * pad], fill=(0, 0, 0))
        for j, text in enumerate(lines):
            draw.text((x0 + pad, pad + line_h * j), text, fill=(255, 255, 255), font=self._font)
        return np.asarray(image)

    def close(self) -> None:
        self.top.close()
        if self.chase is not None:
            self.chase.close()
