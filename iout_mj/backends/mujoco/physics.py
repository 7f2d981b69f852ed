"""dm_control Physics for N AUVs: named accessors, commands, and exact actuator-power metering.

`Stepper` advances one or several AUVPhysics in one `mujoco.rollout` call (all substeps in C,
no Python per substep; several scenes share C threads) and keeps every substep's state and
sensor data, so the mechanical power |force x velocity| of every actuator is integrated over
every substep, and the substep trajectory (`substep_qpos`) is there for smooth video frames
and the separation metrics. `AUVPhysics.step` is the Stepper on one scene.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import mujoco
import numpy as np
from dm_control.mujoco import engine, wrapper
from dm_control.rl.control import PhysicsError
from mujoco import rollout

from iout_mj.backends.mujoco import names, vehicle
from iout_mj.config import MAX_SUBSTEPS_PER_SLOT, Config
from iout_mj.errors import UsageError, require_integer
from iout_mj.types import BoolArray, FloatArray, IntArray
from iout_mj.world import propulsion
from iout_mj.world.geometry import norm_xy, wrap_angle

_STATE_SPEC = mujoco.mjtState.mjSTATE_FULLPHYSICS


def _sensor_adr(model: mujoco.MjModel, name: str) -> int:
    return int(model.sensor_adr[model.sensor(name).id])


def joint_addresses(model: mujoco.MjModel, n_auvs: int, field: str = "jnt_qposadr") -> IntArray:
    """(3, N) qpos (or, with field='jnt_dofadr', dof) addresses of every AUV's x, y, yaw."""
    return np.array(
        [
            [getattr(model, field)[model.joint(names.auv_prefix(i) + j).id] for i in range(n_auvs)]
            for j in (names.JOINT_X, names.JOINT_Y, names.JOINT_YAW)
        ],
        dtype=np.int64,
    )


class AUVPhysics(engine.Physics):
    """Physics of one scene built by `vehicle.build_scene`."""

    @classmethod
    def from_config(cls, cfg: Config) -> AUVPhysics:
        physics = cls.from_model(wrapper.MjModel(vehicle.build_model(cfg)))
        physics.bind(cfg)
        return physics

    def bind(self, cfg: Config) -> None:
        """Look up every index once; per-step code never looks up names."""
        m = self.model.ptr
        n = cfg.scenario.n_auvs
        self.cfg = cfg
        self.n_auvs = n
        self.dt_s = float(m.opt.timestep)

        self._qx, self._qy, self._qyaw = joint_addresses(m, n)
        self._vx, self._vy, self._vyaw = joint_addresses(m, n, "jnt_dofadr")
        self._qxy = np.stack([self._qx, self._qy], axis=1)  # (N, 2): one gather per read
        self._vxy = np.stack([self._vx, self._vy], axis=1)
        self._thrust = np.array(
            [m.actuator(names.auv_prefix(i) + names.THRUST).id for i in range(n)]
        )
        self._yaw_act = np.array(
            [m.actuator(names.auv_prefix(i) + names.YAW_ACTUATOR).id for i in range(n)]
        )
        pairs = [
            (names.THRUST + "_force", names.THRUST + "_velocity"),
            (names.YAW_ACTUATOR + "_force", names.YAW_ACTUATOR + "_velocity"),
        ]
        self._power_sensors = np.array(
            [
                [
                    [
                        _sensor_adr(m, names.auv_prefix(i) + f),
                        _sensor_adr(m, names.auv_prefix(i) + v),
                    ]
                    for f, v in pairs
                ]
                for i in range(n)
            ]
        )  # (N, 2 actuators, 2: force/velocity)
        self._nodes = np.array(
            [m.body(names.node_name(k)).id for k in range(cfg.scenario.n_nodes)], dtype=np.int64
        )
        self._stepper: Stepper | None = Stepper()
        self.meter = propulsion.EnergyMeter(n, cfg.motion)
        """The AUVs' energy meter (measured actuator work)."""
        self.substep_qpos: FloatArray = np.zeros((0, m.nq))
        """(substeps, nq) qpos after every substep of the last step (until the next one)."""

    # ------------------------------------------------------------------ accessors
    # Each reads this physics' state, or the same fields of given qpos / qvel arrays with any
    # leading axes (every physics of one config shares the layout: see `task.book`).
    def positions_m(self, qpos: FloatArray | None = None) -> FloatArray:
        """(..., N, 2) positions."""
        return (self.data.ptr.qpos if qpos is None else qpos)[..., self._qxy]

    def yaw_rad(self, qpos: FloatArray | None = None) -> FloatArray:
        """(..., N) unwrapped yaw angles (continuous across +-pi)."""
        return (self.data.ptr.qpos if qpos is None else qpos)[..., self._qyaw]

    def headings_rad(self, qpos: FloatArray | None = None) -> FloatArray:
        """(..., N) headings wrapped to (-pi, pi]."""
        return wrap_angle(self.yaw_rad(qpos))

    def substep_positions_m(self) -> FloatArray:
        """(substeps, N, 2) positions after every substep of the last `step` call."""
        return self.positions_m(self.substep_qpos)

    def velocities_mps(self, qvel: FloatArray | None = None) -> FloatArray:
        """(..., N, 2) velocities over ground."""
        return (self.data.ptr.qvel if qvel is None else qvel)[..., self._vxy]

    def speeds_mps(self, qvel: FloatArray | None = None) -> FloatArray:
        """(..., N) measured speeds over ground."""
        return norm_xy(self.velocities_mps(qvel))

    def surge_mps(self) -> FloatArray:
        """Measured speed along the hull axis."""
        yaw = self.yaw_rad()
        v = self.velocities_mps()
        return np.cos(yaw) * v[:, 0] + np.sin(yaw) * v[:, 1]

    # ------------------------------------------------------------------ commands
    def _per_auv(self, name: str, values: FloatArray, tail: tuple[int, ...] = ()) -> FloatArray:
        """`values` as a finite array of shape (n_auvs, *tail), or a ValueError naming that
        shape (numpy would broadcast one AUV's values to all of them; MuJoCo would fly NaN)."""
        return _finite_shaped(name, values, (self.n_auvs, *tail), "one row per AUV")

    def set_commands(self, yaw_setpoint_rad: FloatArray, speed_setpoint_mps: FloatArray) -> None:
        """Heading (unwrapped) and speed setpoints for the low-level servos; an AUV on the fence
        and far off its heading turns before it drives (`vehicle.fence_hold`)."""
        yaw_setpoint_rad = self._per_auv("yaw_setpoint_rad", yaw_setpoint_rad)
        speed_setpoint_mps = self._per_auv("speed_setpoint_mps", speed_setpoint_mps)
        hold = vehicle.fence_hold(
            self.positions_m(), self.yaw_rad(), yaw_setpoint_rad, self.cfg.scenario.area_m
        )
        speed_setpoint_mps = np.where(hold, 0.0, speed_setpoint_mps)
        ctrl = self.data.ctrl
        ctrl[self._yaw_act] = yaw_setpoint_rad
        ctrl[self._thrust] = vehicle.thrust_command(np.asarray(speed_setpoint_mps), self.cfg)

    def set_poses(self, xy_m: FloatArray, yaw_rad: FloatArray, speed_mps: FloatArray) -> None:
        """Place every AUV, moving at `speed_mps` along its heading, and zero the meters."""
        xy_m = self._per_auv("xy_m", xy_m, (2,))
        yaw_rad = self._per_auv("yaw_rad", yaw_rad)
        speed_mps = self._per_auv("speed_mps", speed_mps)
        q, v = self.data.qpos, self.data.qvel
        q[self._qx], q[self._qy], q[self._qyaw] = xy_m[:, 0], xy_m[:, 1], yaw_rad
        v[self._vx] = speed_mps * np.cos(yaw_rad)
        v[self._vy] = speed_mps * np.sin(yaw_rad)
        v[self._vyaw] = 0.0
        self.data.ptr.plugin_state[:] = 0.0  # the added mass's force record is of another pose
        self.set_commands(yaw_rad, speed_mps)
        self.meter.reset()
        self.substep_qpos = np.zeros((0, self.model.ptr.nq))
        mujoco.mj_forward(self.model.ptr, self.data.ptr)

    def place_scene(self, nodes_m: FloatArray, current_mps: FloatArray) -> None:
        """Move the node markers and set the ocean current (MuJoCo wind) for an episode."""
        nodes_m = _finite_shaped("nodes_m", nodes_m, (len(self._nodes), 2), "one row per node")
        current_mps = _finite_shaped("current_mps", current_mps, (2,), "(east, north) in m/s")
        m = self.model.ptr
        m.body_pos[self._nodes, :2] = nodes_m
        m.opt.wind[:2] = current_mps

    # ------------------------------------------------------------------ stepping
    @property
    def stepper(self) -> Stepper:
        """The Stepper of this scene (its `recorded` list is the benchmark's hook)."""
        assert self._stepper is not None, "used after free()"
        return self._stepper

    def step(self, nstep: int = 1) -> None:
        """Advance `nstep` substeps in C and integrate actuator power over each of them."""
        assert self._stepper is not None, "stepped after free()"
        if self._stepper.step([self], nstep)[0]:
            raise PhysicsError(DIVERGED)

    def actuator_work_j(self, sensordata: FloatArray) -> FloatArray:
        """(..., N, 2) integral of |force x velocity| of each AUV's thrust and yaw actuators
        over recorded (..., substeps, nsensordata) sensor data."""
        force = sensordata[..., self._power_sensors[..., 0]]
        velocity = sensordata[..., self._power_sensors[..., 1]]
        return np.abs(force * velocity).sum(axis=-3) * self.dt_s

    def __getstate__(self) -> Any:
        raise TypeError("AUVPhysics is not picklable; pickle the environment (it rebuilds).")

    def free(self) -> None:
        stepper = getattr(self, "_stepper", None)
        if stepper is not None:
            stepper.close()
            self._stepper = None
        super().free()


def _finite_shaped(name: str, values: Any, shape: tuple[int, ...], meaning: str) -> FloatArray:
    """`values` as a float array of exactly `shape` and finite, or a ValueError saying so."""
    arr = np.asarray(values, dtype=float)
    if arr.shape != shape:
        raise ValueError(f"{name} has shape {arr.shape}; accepted: {shape}, {meaning}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} holds NaN or infinity; accepted finite values, {meaning}")
    return arr


DIVERGED = "physics diverged: MuJoCo found a bad position, velocity or acceleration and reset"


class Stepper:
    """Advances several AUVPhysics of the same scene size together: one `mujoco.rollout`
    call runs every substep in C (on `nthread` threads when > 0), records every substep's
    state and sensor data, and each physics meters its actuator power from them."""

    def __init__(self, nthread: int = 0):
        self.nthread = nthread
        self._rollout = rollout.Rollout(nthread=nthread)
        self._scratch: list[mujoco.MjData] = []
        self._shape = (0, 0)  # (scenes, nstep) the buffers below are sized for
        self._buffers: tuple[FloatArray, ...] = ()
        self.recorded: list[tuple[FloatArray, FloatArray]] | None = None
        """Set to a list to keep every scene's (start state, first control) of every step (the
        benchmark replays them through plain `mj_step`)."""

    def step(self, physics: Sequence[AUVPhysics], nstep: int) -> BoolArray:
        """Advance every physics `nstep` substeps; returns which of them diverged (MuJoCo
        reset its state, or it is not finite) in the meantime.

        Raises:
            UsageError: no physics, or `nstep` is not an integer from 1 to the substeps a slot
                may have.
            ValueError: physics of scenes of different sizes (another N).
        """
        if not physics:
            raise UsageError("no physics to step: accepted one or more AUVPhysics")
        require_integer(nstep, "nstep", 1, MAX_SUBSTEPS_PER_SLOT)
        models = [p.model.ptr for p in physics]
        m = models[0]
        if not self._scratch:  # one workspace per thread; each physics keeps its own data
            self._scratch = [mujoco.MjData(m) for _ in range(max(self.nthread, 1))]
        if self._shape != (len(physics), nstep):
            self._shape, nstate = (len(physics), nstep), mujoco.mj_stateSize(m, _STATE_SPEC)
            self._buffers = (
                np.empty((len(physics), nstate)),
                np.empty((len(physics), nstep, m.nu)),
                np.empty((len(physics), nstep, nstate)),
                np.empty((len(physics), nstep, m.nsensordata)),
            )
        state0, ctrl, state, sensordata = self._buffers
        try:  # MuJoCo checks each state's size; the rollout below (skip_checks) would not
            for i, p in enumerate(physics):
                mujoco.mj_getState(models[i], p.data.ptr, state0[i], _STATE_SPEC)
                ctrl[i] = p.data.ptr.ctrl
        except (TypeError, ValueError) as exc:
            raise ValueError(
                "the physics stepped together are scenes of different sizes: accepted "
                f"AUVPhysics of one config's N ({exc})"
            ) from exc
        if self.recorded is not None:
            self.recorded.extend((state0[i].copy(), ctrl[i, 0].copy()) for i in range(len(physics)))
        self._rollout.rollout(
            models,
            self._scratch,
            state0,
            ctrl,
            nstep=nstep,
            skip_checks=True,
            state=state,
            sensordata=sensordata,
        )
        # A MuJoCo auto-reset (bad qpos/qvel/qacc) restarts the clock: the slot's end time shows it.
        end_s = state0[:, 0] + nstep * m.opt.timestep  # one config: one timestep
        diverged = ~np.isfinite(state[:, -1]).all(axis=1) | (
            np.abs(state[:, -1, 0] - end_s) > 0.5 * m.opt.timestep
        )
        work_j = physics[0].actuator_work_j(sensordata)  # same sensor layout for all
        nq = m.nq
        for i, p in enumerate(physics):
            mujoco.mj_setState(models[i], p.data.ptr, state[i, -1], _STATE_SPEC)
            p.meter.add(work_j[i])
            p.substep_qpos = state[i, :, 1 : 1 + nq]  # a view: valid until the next step
        return diverged

    def close(self) -> None:
        self._rollout.close()
