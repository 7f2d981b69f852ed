"""The hulls' planar added mass: loading the MuJoCo plugin "iout.added_mass" (added_mass.c).

Each MJCF file declares an instance of the plugin with its hull body's name and X_udot, Y_vdot
and Y_rdot; the plugin must be registered before MuJoCo reads them, so importing `vehicle`
loads it. Which terms come
from where: the body's mass carries -X_udot and its I_zz -N_rdot; the plugin the rest of
-M_A nu_dot (sway beyond surge, sway-yaw coupling) and every added-mass Coriolis (Munk) term;
MuJoCo's ellipsoid fluid model only drag and lift (`disable_fluid_added_mass` removes its own
added-mass terms, which would count the Munk moment twice).
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from iout_mj.errors import IoutError
from iout_mj.types import FloatArray, IntArray

PLUGIN = "iout.added_mass"
"""The plugin's registered name (the MJCF's `<plugin plugin=...>`)."""
NSTATE = 10
"""Plugin state per instance (added_mass.c): F_o (3, body axes), F_p (3, world), qvel (3), yaw."""
FLUID_ADDED_MASS = slice(6, 12)
"""MuJoCo's virtual mass and inertia in each row of `geom_fluid` (its ellipsoid model)."""

_library: ctypes.CDLL | None = None


def load() -> None:
    """Register the plugin with MuJoCo (once per process)."""
    global _library
    if _library is not None:
        return
    found = sorted(Path(__file__).parent.glob("_added_mass*.so"))
    if not found:
        raise IoutError(
            "the added-mass MuJoCo plugin is not built (iout_mj/backends/mujoco/_added_mass*.so "
            "is missing): run `pip install -e .` in the project folder"
        )
    try:  # its constructor registers the plugin with the libmujoco this process loaded
        _library = ctypes.CDLL(str(found[0]))
    except OSError as exc:
        raise IoutError(
            f"the added-mass MuJoCo plugin does not load with MuJoCo {mujoco.__version__} "
            f"({exc}): it is built for one MuJoCo version; rebuild it with `pip install -e .`"
        ) from exc


def attach_instance(scene: mujoco.MjSpec, auv: mujoco.MjSpec, prefix: str) -> None:
    """Give the AUV copy `prefix` of `auv` (just attached to `scene`) its own plugin instance:
    the AUV's configuration, on the copy's body (MjSpec.attach does not copy instances)."""
    (own,) = [p for p in auv.plugins if p.plugin_name == PLUGIN]
    scene.activate_plugin(PLUGIN)
    instance = scene.add_plugin(name=prefix + own.name, plugin_name=PLUGIN)
    instance.config = {**own.config, "body": prefix + own.config["body"]}


def disable_fluid_added_mass(model: mujoco.MjModel, geoms: list[int]) -> None:
    """Zero MuJoCo's own added mass (virtual mass and inertia) of the ellipsoid geoms `geoms`:
    the plugin applies the hull's."""
    for g in geoms:
        model.geom_fluid[g, FLUID_ADDED_MASS] = 0.0


@dataclass(frozen=True)
class Hulls:
    """Every plugin instance of a compiled model, as added_mass.c reads it (the MuJoCo Warp
    stepper applies the same terms with these)."""

    dofs: IntArray
    """(H, 3) dof addresses of x, y, yaw."""
    qpos_yaw: IntArray
    """(H,) qpos address of yaw."""
    coefficients: FloatArray
    """(H, 9): m_b (kg), I_b (kg m^2), D = X_udot - Y_vdot (kg), c = -Y_rdot (kg m), then the
    hull terms yvv, yrr, nvv, yuv, nuv."""


def hulls(model: mujoco.MjModel) -> Hulls:
    """The plugin instances of `model` (all of its plugins: the scene has no other)."""
    attributes = bytes(model.plugin_attr)
    dofs, qpos_yaw, coefficients = [], [], []
    for i in range(model.nplugin):
        # body, xudot, yvdot, yrdot, yvv, yrr, nvv, yuv, nuv (added_mass.c's ATTRIBUTES)
        body, *values = attributes[int(model.plugin_attradr[i]) :].split(b"\0")[:9]
        x_udot, y_vdot, y_rdot, *hull = (float(v or 0) for v in values)
        b = model.body(body.decode())
        joints = range(int(b.jntadr[0]), int(b.jntadr[0]) + 3)
        dofs.append([int(model.jnt_dofadr[j]) for j in joints])
        qpos_yaw.append(int(model.jnt_qposadr[joints[2]]))
        coefficients.append(
            [float(b.mass[0]), float(b.inertia[2]), x_udot - y_vdot, -y_rdot, *hull]
        )
    return Hulls(
        np.array(dofs, dtype=np.int64).reshape(-1, 3),
        np.array(qpos_yaw, dtype=np.int64),
        np.array(coefficients, dtype=np.float64).reshape(-1, 9),
    )
