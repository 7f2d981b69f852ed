"""iout-mj: physics-grounded multi-AUV data collection for the Internet of Underwater Things."""

import os

# Headless by default: MuJoCo's offscreen renderer through EGL (Mesa's llvmpipe without a GPU).
os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])

__version__ = "0.1.0"


def _register() -> None:
    import gymnasium

    if "iout_mj/MultiAUV-v0" not in gymnasium.registry:
        gymnasium.register(id="iout_mj/MultiAUV-v0", entry_point="iout_mj.envs:MultiAUVEnv")


_register()
