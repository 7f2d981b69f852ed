"""The MuJoCo plugin of the hulls' planar added mass (iout_mj/backends/mujoco/added_mass.c).

Everything else of the build is in pyproject.toml; this extension is here because it compiles
against the headers and library of the installed MuJoCo wheel, whose path only Python knows
(pyproject.toml's build-system requires the same MuJoCo range as the package). It links to
libmujoco.so.X.Y.Z by its versioned name, so a MuJoCo upgrade needs a rebuild
(`pip install -e .`), and loading says so (iout_mj/backends/mujoco/added_mass.py).
"""

from pathlib import Path

import mujoco
from setuptools import Extension, setup

MUJOCO_DIR = Path(mujoco.__file__).parent
LIBMUJOCO = sorted(MUJOCO_DIR.glob("libmujoco.so.*")) or sorted(MUJOCO_DIR.glob("libmujoco*.dylib"))

setup(
    ext_modules=[
        Extension(
            "iout_mj.backends.mujoco._added_mass",
            sources=["iout_mj/backends/mujoco/added_mass.c"],
            include_dirs=[str(MUJOCO_DIR / "include")],
            extra_objects=[str(LIBMUJOCO[0])],
            extra_compile_args=["-O2", "-std=gnu11", "-Wall", "-Wextra", "-Wno-unused-parameter"],
        )
    ]
)
