"""Offscreen mission rendering (EGL, OSMesa fallback): a top-down map beside a chase view of
the first AUV still under way, with trails, links, node state, and beside the map a text panel
(`overlay`); several frames per slot from the physics substeps.

Built from a model of the scene and a `Mission`: the renderer reads the mission state, never
the env. Nothing renders unless a frame is asked for.
"""

from __future__ import annotations

import itertools
import os

import mujoco
import numpy as np
from numpy.typing import NDArray
from PIL import Image, ImageDraw

import iout_mj
from iout_mj import palette
from iout_mj.backends.mujoco import names, overlay, vehicle
from iout_mj.backends.mujoco.physics import AUVPhysics, joint_addresses
from iout_mj.errors import IoutError
from iout_mj.mission import Mission
from iout_mj.mission.observation import node_energy_level
from iout_mj.types import FloatArray
from iout_mj.world.geometry import wrap_angle

TRAIL_POINTS = 400
MARKER_LENGTH_M = 40.0
LINK_WIDTH_PX = 3.0
HULL_MATERIAL = "hull"
"""assets/auv.xml's hull material."""
Z_AUV_M = vehicle.AUV_DEPTH_M
Z_NODE_M = vehicle.SEABED_DEPTH_M + 4.5
"""Height of the node discs drawn over the node bodies."""


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

    The frame (`overlay.frame_layout`) is the top-down map of the whole area, labelled (node
    indices, AUV numbers, a scale bar), beside a column with a chase view over a text panel
    (time, AoI now and so far, Jain, data, each AUV's energy and docking, the AoI colour bar,
    the link colours). The chase camera rides the first AUV still under way (the last one to
    dock, once all have). Too narrow a frame is the map alone. With `physics` (the MuJoCo
    backend) the frames of a slot come from its substeps; without (the kinematic backend) the
    vehicles are placed along straight lines. One class (over the house's ~150 lines): poses,
    trails, decorations and labels share the two views' scenes.
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
        self.layout = lay = overlay.frame_layout(width, height)
        self.top = make_renderer(self.model, lay.map_h, lay.map_w)
        self.chase = make_renderer(self.model, lay.chase_h, lay.side_w) if lay.side_w else None
        self._qx, self._qy, self._qyaw = joint_addresses(self.model, self.mission.n_auvs)
        self._nodes = [model.body(names.node_name(k)).id for k in range(mission.n_nodes)]
        self._top_cam = model.camera(names.TOP_CAMERA).id
        for i in range(mission.n_auvs):  # each hull in its AUV's colour (the chase view)
            model.material(names.auv_prefix(i) + HULL_MATERIAL).rgba = palette.AUV_RGBA[i % 4]
        sc = self.cfg.scenario
        sample = overlay.worst_case(
            sc.horizon_slots, sc.slot_s, mission.n_auvs, self.cfg.network.aoi_max
        )
        self._panel = overlay.Panel(lay.side_w, lay.panel_h, sample) if lay.side_w else None
        self._labels = overlay.MapLabels(lay.map_h)
        self.reset()

    def reset(self) -> None:
        """Start a new episode: clear trails and frames, place this episode's node markers."""
        self.model.body_pos[self._nodes, :2] = self.mission.network.nodes_m
        self.trails: list[list[FloatArray]] = [[] for _ in range(self.mission.n_auvs)]
        self.docked_at: list[int | None] = [None] * self.mission.n_auvs
        self.chased = 0
        self._slot_start_pose = self._pose_now()
        self._pending: list[NDArray[np.uint8]] = []
        self._panel_cache: tuple[tuple, NDArray[np.uint8]] | None = None

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
        `keep_frames`, render its frames for `take_frames`. The chase camera stays on its AUV
        through the slot in which it docks, then moves on to the first one still under way."""
        docked = self.mission.state.docked
        for j in np.flatnonzero(docked):
            if self.docked_at[j] is None:
                self.docked_at[j] = int(self.mission.state.slot)
        for xy, yaw in self._substep_poses():
            for i in range(self.mission.n_auvs):
                self.trails[i].append(xy[i].copy())
            if keep_frames:
                self._pending.append(self._compose(xy, yaw))
        self._slot_start_pose = self._pose_now()
        under_way = np.flatnonzero(~docked)
        if docked[self.chased] and len(under_way):
            self.chased = int(under_way[0])

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
        top = self.top.render()
        if self.chase is None or self._panel is None:
            return top
        lay = self.layout
        img = np.empty((lay.height, lay.width, 3), np.uint8)
        img[:] = overlay.PANEL_RGB
        img[lay.map_top : lay.map_top + lay.map_h, : lay.map_w] = top
        self.chase.update_scene(d, camera=names.auv_prefix(self.chased) + names.CHASE_CAMERA)
        self._decorate(self.chase.scene, xy, yaw, top=False)
        img[: lay.chase_h, lay.map_w :] = self.chase.render()
        img[lay.chase_h :, lay.map_w :] = self._panel_image()
        return self._label_map(img, d, xy, yaw)

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

    def _node_radii_m(self) -> FloatArray:
        """Node disc radii: size = stored energy (log scale)."""
        level = node_energy_level(self.mission.network.energy_j)
        return vehicle.NODE_RADIUS_M * (0.8 + 1.75 * level)

    def _decorate(self, scene: mujoco.MjvScene, xy: FloatArray, yaw: FloatArray, top: bool) -> None:
        mission, net = self.mission, self.mission.network
        # Nodes: colour = AoI, size = stored energy.
        radius = self._node_radii_m()
        colors = palette.aoi_rgba(net.aoi / self.cfg.network.aoi_max)
        for k, (x, y) in enumerate(net.nodes_m):
            g = self._add(scene)
            if g is None:
                break
            mujoco.mjv_initGeom(
                g,
                mujoco.mjtGeom.mjGEOM_CYLINDER,
                np.array([radius[k], radius[k], 1.5]),
                np.array([x, y, Z_NODE_M]),
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
                p = np.array([xy[i, 0], xy[i, 1], Z_AUV_M])
                q_aet = np.array([*net.nodes_m[aet[i]], Z_NODE_M])
                q_up = np.array([*net.nodes_m[up[i]], Z_NODE_M + 1])
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
                self._line(scene, np.array([*a, Z_AUV_M]), np.array([*b, Z_AUV_M]), color, 2.0)
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
                    np.array([xy[i, 0], xy[i, 1], Z_AUV_M]),
                    mat.ravel(),
                    color.astype(np.float32),
                )

    # ------------------------------------------------------------------ 2-D layer
    def _panel_state(self) -> overlay.PanelState:
        m, sc = self.mission, self.cfg.scenario
        slot = int(m.state.slot)
        return overlay.PanelState(
            time_s=slot * sc.slot_s,
            slot=slot,
            horizon_slots=sc.horizon_slots,
            aoi_now=float(m.network.mean_aoi),
            aoi_so_far=float(m.metrics()["mean_aoi"]),
            jain=float(m.network.jain),
            data_mbit=float(m.network.delivered_bits) / 1e6,
            energy_kj=tuple(float(e) / 1e3 for e in m.state.propulsion_energy_j),
            docked=tuple(bool(b) for b in m.state.docked),
            docked_at=tuple(self.docked_at),
            chased=self.chased,
            aoi_max=self.cfg.network.aoi_max,
        )

    def _panel_image(self) -> NDArray[np.uint8]:
        """The text panel, drawn once per slot (the state it shows changes per slot)."""
        assert self._panel is not None
        key = (int(self.mission.state.slot), self.chased, tuple(self.docked_at))
        if self._panel_cache is None or self._panel_cache[0] != key:
            self._panel_cache = key, self._panel.image(self._panel_state())
        return self._panel_cache[1]

    def _label_map(
        self, img: NDArray[np.uint8], d: mujoco.MjData, xy: FloatArray, yaw: FloatArray
    ) -> NDArray[np.uint8]:
        """Node indices, AUV numbers and a scale bar on the map of the composed frame."""
        lay, cam = self.layout, self._top_cam
        sc = self.cfg.scenario

        def pixels(points_m: FloatArray) -> FloatArray:
            px = overlay.project(
                points_m,
                d.cam_xpos[cam],
                d.cam_xmat[cam],
                float(self.model.cam_fovy[cam]),
                lay.map_w,
                lay.map_h,
            )
            return px + np.array([0.0, lay.map_top])

        net = self.mission.network
        nodes = np.column_stack([net.nodes_m, np.full(len(net.nodes_m), Z_NODE_M)])
        rims = nodes + np.column_stack([self._node_radii_m(), np.zeros((len(nodes), 2))])
        nodes_px, rims_px = pixels(nodes), pixels(rims)
        auvs_px = pixels(np.column_stack([xy, np.full(len(xy), Z_AUV_M)]))
        ax = sc.area_m[0]
        dock_x, dock_y = sc.dock_center_m
        dock = np.array([[dock_x, dock_y, Z_NODE_M], [dock_x, dock_y - sc.dock_radius_m, Z_NODE_M]])
        corner = pixels(np.array([[0.0, 0.0, Z_NODE_M], [ax, 0.0, Z_NODE_M]]))
        image = Image.fromarray(img)
        draw = ImageDraw.Draw(image)
        self._labels.nodes(draw, nodes_px, rims_px[:, 0] - nodes_px[:, 0])
        self._labels.dock(draw, pixels(dock)[1])
        self._labels.auvs(draw, auvs_px, yaw, tuple(bool(b) for b in self.mission.state.docked))
        (left, bottom), (right, _) = corner
        self._labels.scale_bar(
            draw, (right, bottom + 2), (right - left) / ax, ax, lay.map_top + lay.map_h
        )
        return np.asarray(image)

    def close(self) -> None:
        self.top.close()
        if self.chase is not None:
            self.chase.close()
