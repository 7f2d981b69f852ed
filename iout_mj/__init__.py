"""iout-mj: physics-grounded multi-AUV data collection for the Internet of Underwater Things."""

import os
from ctypes.util import find_library
from typing import Any

import gymnasium  # does not import mujoco: the GL backend is still free to choose

__version__ = "0.1.0"

_GL_LIBRARIES = {"egl": "EGL", "osmesa": "OSMesa"}
GL_NOTE = ""
"""Why the offscreen GL backend differs from the one asked for (empty when it does not)."""


def _choose_gl_backend() -> None:
    """Headless rendering: EGL (Mesa's llvmpipe without a GPU), else OSMesa, else disabled.

    Must run before mujoco is imported: mujoco binds its GL backend at import and fails to
    import at all when MUJOCO_GL names a library that is missing.
    """
    global GL_NOTE
    requested = os.environ.get("MUJOCO_GL", "egl").lower()
    if requested not in _GL_LIBRARIES:
        return  # glfw, disable, ...: the user's choice stands
    chosen = next(
        (b for b in dict.fromkeys([requested, *_GL_LIBRARIES]) if find_library(_GL_LIBRARIES[b])),
        None,
    )
    if chosen is None:
        GL_NOTE = (
            f"MUJOCO_GL={requested}: neither libEGL nor libOSMesa is installed; "
            "rendering is disabled"
        )
        chosen = "disable"
    elif chosen != requested:
        GL_NOTE = f"MUJOCO_GL={requested}: lib{_GL_LIBRARIES[requested]} is missing; using {chosen}"
    os.environ["MUJOCO_GL"] = chosen
    if chosen != "disable":
        os.environ["PYOPENGL_PLATFORM"] = chosen


def _register() -> None:
    if "iout_mj/MultiAUV-v0" not in gymnasium.registry:
        gymnasium.register(
            id="iout_mj/MultiAUV-v0",
            entry_point="iout_mj.envs.gym_env:MultiAUVEnv",
            vector_entry_point="iout_mj.envs.gym_vector:MultiAUVVectorEnv",
        )


def parallel_env(**kwargs: Any) -> Any:
    """The PettingZoo ParallelEnv, one agent per AUV (`envs.parallel_env`)."""
    from iout_mj.envs.parallel_env import parallel_env as make  # pettingzoo: only when asked

    return make(**kwargs)


_choose_gl_backend()
_register()
