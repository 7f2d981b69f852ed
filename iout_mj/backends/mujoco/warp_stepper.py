"""MuJoCo Warp stepping of B scenes at once: the `Stepper` interface on a GPU (or Warp's CPU
device), so that the mission, the energy meter and the videos stay those of the C backend.

Every AUVPhysics stays the host mirror of its world: once per slot its state, controls and
current go to the device, `mujoco_warp.step` runs the substeps (captured once as a CUDA graph
on a GPU), a small kernel after every substep integrates |force x velocity| of every actuator
(the C backend's meter) and records the positions (the separation metric, video replay), and
the slot's end state comes back. MuJoCo Warp computes in float32: positions near 700 m would
keep only ~60 um, so each world's x and y are re-based to the AUVs' start of slot, with the
arena's walls (the slide joints' limits) moved by the same offsets (the scene has no contacts
and a uniform current: nothing else depends on absolute position); the offsets are added back
in float64.

MuJoCo Warp runs no C plugin: the hulls' added mass (the C backend's iout.added_mass plugin) is
applied here by two kernels with the same equations, one before every substep (its force, as
`qfrc_applied`) and one after (the hull's other forces, from the velocity change); its state
goes to the device and back with each physics' plugin state.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from iout_mj.backends.mujoco import added_mass, vehicle
from iout_mj.types import BoolArray

GPU_EXTRA = "pip install 'iout-mj[gpu]' (mujoco-warp and warp-lang)"


def _import_warp() -> tuple[Any, Any]:
    try:
        import mujoco_warp as mjw
        import warp as wp
    except ImportError as exc:
        raise ImportError(f"backend 'warp' needs MuJoCo Warp: {GPU_EXTRA} ({exc})") from exc
    wp.config.quiet = True  # type: ignore[attr-defined]
    return wp, mjw


def default_device() -> str:
    """'cuda' when Warp sees a GPU, else 'cpu'."""
    wp, _ = _import_warp()
    wp.init()
    return "cuda" if wp.is_cuda_available() else "cpu"


_KERNELS: dict[str, Any] = {}


def _kernels() -> dict[str, Any]:
    """The two per-substep kernels (defined on first use: importing warp is optional)."""
    if _KERNELS:
        return _KERNELS
    wp, _ = _import_warp()

    @wp.kernel
    def meter(
        sensordata: wp.array2d(dtype=float),  # type: ignore[valid-type]
        force_adr: wp.array(dtype=int),  # type: ignore[valid-type]
        velocity_adr: wp.array(dtype=int),  # type: ignore[valid-type]
        dt: float,
        work: wp.array2d(dtype=float),  # type: ignore[valid-type]
    ) -> None:
        w, p = wp.tid()
        work[w, p] += wp.abs(sensordata[w, force_adr[p]] * sensordata[w, velocity_adr[p]]) * dt

    @wp.kernel
    def record(
        qpos: wp.array2d(dtype=float),  # type: ignore[valid-type]
        substep: int,
        path: wp.array3d(dtype=float),  # type: ignore[valid-type]
    ) -> None:
        w, j = wp.tid()
        path[substep, w, j] = qpos[w, j]

    @wp.kernel
    def added_mass_force(
        qpos: wp.array2d(dtype=float),  # type: ignore[valid-type]
        qvel: wp.array2d(dtype=float),  # type: ignore[valid-type]
        wind: wp.array(dtype=wp.vec3),  # type: ignore[valid-type]
        dofs: wp.array2d(dtype=int),  # type: ignore[valid-type]
        qpos_yaw: wp.array(dtype=int),  # type: ignore[valid-type]
        coef: wp.array2d(dtype=float),  # type: ignore[valid-type]
        state: wp.array3d(dtype=float),  # type: ignore[valid-type]
        qfrc_applied: wp.array2d(dtype=float),  # type: ignore[valid-type]
    ) -> None:
        w, h = wp.tid()  # added_mass.c's compute(), line for line
        mb, ib, dm, c = coef[h, 0], coef[h, 1], coef[h, 2], coef[h, 3]
        yaw = qpos[w, qpos_yaw[h]]
        cy, sy = wp.cos(yaw), wp.sin(yaw)
        vx = qvel[w, dofs[h, 0]] - wind[w][0]
        vy = qvel[w, dofs[h, 1]] - wind[w][1]
        u, v, r = cy * vx + sy * vy, -sy * vx + cy * vy, qvel[w, dofs[h, 2]]
        hv = coef[h, 4] * v * wp.abs(v) + coef[h, 5] * r * wp.abs(r) + coef[h, 7] * u * v
        hr = coef[h, 6] * v * wp.abs(v) + coef[h, 8] * u * v
        gv = state[w, h, 1] + hv - mb * r * u
        gr = state[w, h, 2] + hr - dm * u * v - c * u * r
        det = (mb + dm) * ib - c * c
        vdot = (ib * gv - c * gr) / det
        rdot = ((mb + dm) * gr - c * gv) / det
        fu = dm * v * r + c * r * r
        fv = mb * vdot - gv + hv
        fr = ib * rdot - state[w, h, 2]
        fx, fy = cy * fu - sy * fv, sy * fu + cy * fv
        qfrc_applied[w, dofs[h, 0]] = fx
        qfrc_applied[w, dofs[h, 1]] = fy
        qfrc_applied[w, dofs[h, 2]] = fr
        state[w, h, 3] = fx
        state[w, h, 4] = fy
        state[w, h, 5] = fr
        for j in range(3):
            state[w, h, 6 + j] = qvel[w, dofs[h, j]]
        state[w, h, 9] = yaw

    @wp.kernel
    def added_mass_update(
        qvel: wp.array2d(dtype=float),  # type: ignore[valid-type]
        qfrc_constraint: wp.array2d(dtype=float),  # type: ignore[valid-type]
        dofs: wp.array2d(dtype=int),  # type: ignore[valid-type]
        coef: wp.array2d(dtype=float),  # type: ignore[valid-type]
        rate: float,
        state: wp.array3d(dtype=float),  # type: ignore[valid-type]
    ) -> None:
        w, h = wp.tid()  # added_mass.c's advance()
        x, y, z = dofs[h, 0], dofs[h, 1], dofs[h, 2]
        fx = coef[h, 0] * (qvel[w, x] - state[w, h, 6]) * rate - state[w, h, 3]
        fy = coef[h, 0] * (qvel[w, y] - state[w, h, 7]) * rate - state[w, h, 4]
        fr = coef[h, 1] * (qvel[w, z] - state[w, h, 8]) * rate - state[w, h, 5]
        fx -= qfrc_constraint[w, x]
        fy -= qfrc_constraint[w, y]
        fr -= qfrc_constraint[w, z]
        cy, sy = wp.cos(state[w, h, 9]), wp.sin(state[w, h, 9])
        state[w, h, 0] = cy * fx + sy * fy
        state[w, h, 1] = -sy * fx + cy * fy
        state[w, h, 2] = fr

    _KERNELS.update(
        meter=meter,
        record=record,
        added_mass_force=added_mass_force,
        added_mass_update=added_mass_update,
    )
    return _KERNELS


class WarpStepper:
    """Advances several AUVPhysics of one config together on MuJoCo Warp; `step` has the
    contract of `physics.Stepper.step`.

    Args:
        device: "cuda", "cuda:N" or "cpu"; None takes a GPU when there is one.
        graph: capture the substep loop as a CUDA graph (GPU only).
    """

    def __init__(self, device: str | None = None, graph: bool = True):
        self.wp, self.mjw = _import_warp()
        self.wp.init()
        self.device = device or default_device()
        self.use_graph = graph and self.device.startswith("cuda")
        self._shape: tuple[int, int] = (0, 0)
        self._graph: Any = None
        self.recorded = None  # the C Stepper's benchmark hook; not kept here

    def _build(self, physics: Sequence[Any], nstep: int) -> None:
        wp, mjw = self.wp, self.mjw
        p0, b = physics[0], len(physics)
        mjm = p0.model.ptr
        pairs = p0._power_sensors.reshape(-1, 2)  # (N * 2 actuators, force/velocity)
        # MuJoCo Warp refuses a model with C plugins: the same scene without them (the mission
        # changes no model field but the markers' positions and the current, set per slot)
        device_model = vehicle.build_model(p0.cfg, plugin=False)
        with wp.ScopedDevice(self.device):
            self.model = mjw.put_model(device_model)
            self.data = mjw.make_data(device_model, nworld=b)
            self.wind = wp.zeros(b, dtype=wp.vec3)
            self.model.opt.wind = self.wind  # one current per world
            self.force_adr = wp.array(pairs[:, 0].astype(np.int32), dtype=int)
            self.velocity_adr = wp.array(pairs[:, 1].astype(np.int32), dtype=int)
            # the joint limits (the arena's walls) move with each world's re-based origin
            self.base_range = np.tile(mjm.jnt_range, (b, 1, 1))
            self.jnt_range = wp.array(self.base_range.astype(np.float32), dtype=wp.vec2)
            self.model.jnt_range = self.jnt_range
            self.work = wp.zeros((b, len(pairs)), dtype=float)
            self.path = wp.zeros((nstep, b, mjm.nq), dtype=float)
            hulls = added_mass.hulls(mjm)
            self.hull_dofs = wp.array(hulls.dofs.astype(np.int32), dtype=int)
            self.hull_qpos_yaw = wp.array(hulls.qpos_yaw.astype(np.int32), dtype=int)
            self.hull_coef = wp.array(hulls.coefficients.astype(np.float32), dtype=float)
            self.hull_state = wp.zeros((b, len(hulls.dofs), added_mass.NSTATE), dtype=float)
        self._shape, self._graph = (b, nstep), None
        self._xy = np.concatenate([p0._qx, p0._qy])
        self._joint_qpos = mjm.jnt_qposadr.copy()  # slide and hinge joints: one entry each
        self.dt_s = float(mjm.opt.timestep)

    def _substeps(self, nstep: int) -> None:
        wp, k = self.wp, _kernels()
        b, nq = self._shape[0], self.path.shape[2]
        nhull = self.hull_state.shape[1]
        for s in range(nstep):
            if nhull:
                wp.launch(
                    k["added_mass_force"],
                    dim=(b, nhull),
                    inputs=[
                        self.data.qpos,
                        self.data.qvel,
                        self.wind,
                        self.hull_dofs,
                        self.hull_qpos_yaw,
                        self.hull_coef,
                        self.hull_state,
                    ],
                    outputs=[self.data.qfrc_applied],
                )
            self.mjw.step(self.model, self.data)
            if nhull:
                wp.launch(
                    k["added_mass_update"],
                    dim=(b, nhull),
                    inputs=[
                        self.data.qvel,
                        self.data.qfrc_constraint,
                        self.hull_dofs,
                        self.hull_coef,
                        1.0 / self.dt_s,
                    ],
                    outputs=[self.hull_state],
                )
            wp.launch(
                k["meter"],
                dim=(b, self.work.shape[1]),
                inputs=[self.data.sensordata, self.force_adr, self.velocity_adr, self.dt_s],
                outputs=[self.work],
            )
            wp.launch(k["record"], dim=(b, nq), inputs=[self.data.qpos, s], outputs=[self.path])

    def _run(self, nstep: int) -> None:
        wp = self.wp
        if not self.use_graph:
            self._substeps(nstep)
            return
        if self._graph is None:
            with wp.ScopedDevice(self.device), wp.ScopedCapture() as capture:
                self._substeps(nstep)
            self._graph = capture.graph
        wp.capture_launch(self._graph)

    def step(self, physics: Sequence[Any], nstep: int) -> BoolArray:
        """Advance every physics `nstep` substeps; returns which of them diverged (not
        finite at the end of the slot)."""
        if self._shape != (len(physics), nstep):
            self._build(physics, nstep)
        wp = self.wp
        qpos = np.stack([p.data.ptr.qpos for p in physics])
        offset = np.zeros_like(qpos)
        offset[:, self._xy] = qpos[:, self._xy]
        with wp.ScopedDevice(self.device):
            self.data.qpos.assign((qpos - offset).astype(np.float32))
            self.data.qvel.assign(np.stack([p.data.ptr.qvel for p in physics]).astype(np.float32))
            self.data.ctrl.assign(np.stack([p.data.ptr.ctrl for p in physics]).astype(np.float32))
            self.data.qacc_warmstart.zero_()
            self.wind.assign(np.stack([p.model.ptr.opt.wind for p in physics]).astype(np.float32))
            shift = offset[:, self._joint_qpos][..., None]
            self.jnt_range.assign((self.base_range - shift).astype(np.float32))
            self.work.zero_()
            plugin_state = np.stack([p.data.ptr.plugin_state for p in physics])
            self.hull_state.assign(plugin_state.reshape(self.hull_state.shape).astype(np.float32))
            self._run(nstep)
            wp.synchronize_device(self.device)
            end_qpos = self.data.qpos.numpy().astype(np.float64) + offset
            end_qvel = self.data.qvel.numpy().astype(np.float64)
            path = self.path.numpy().astype(np.float64) + offset[None]
            work = self.work.numpy().astype(np.float64).reshape(len(physics), -1, 2)
            plugin_state = self.hull_state.numpy().astype(np.float64).reshape(len(physics), -1)
        diverged = ~(np.isfinite(end_qpos).all(axis=1) & np.isfinite(end_qvel).all(axis=1))
        for i, p in enumerate(physics):
            d = p.data.ptr
            d.qpos[:], d.qvel[:] = end_qpos[i], end_qvel[i]
            d.plugin_state[:] = plugin_state[i]
            d.time += nstep * self.dt_s
            p.meter.add(work[i])
            p.substep_qpos = path[:, i]
        return diverged

    def close(self) -> None:
        self._graph = None
