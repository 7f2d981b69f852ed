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
from pathlib import Path

import mujoco

from iout_mj.errors import IoutError

PLUGIN = "iout.added_mass"
"""The plugin's registered name (the MJCF's `<plugin plugin=...>`)."""
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
