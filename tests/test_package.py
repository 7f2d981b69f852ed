"""The built package: the wheel carries the MJCF assets and the compiled mission rules."""

import ctypes
import subprocess
import sys
import zipfile

import pytest
from conftest import ROOT

from iout_mj import native


@pytest.mark.slow
def test_wheel_carries_the_assets_and_a_working_compiled_library(tmp_path):
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--quiet",
            "--no-deps",
            str(ROOT),
            "-w",
            str(tmp_path),
        ],
        check=True,
        capture_output=True,
    )
    (wheel,) = tmp_path.glob("iout_mj-*.whl")
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
        assert {"iout_mj/assets/auv.xml", "iout_mj/assets/arena.xml"} <= names
        (library,) = [n for n in names if n.startswith("iout_mj/_native") and n.endswith(".so")]
        plugin = "iout_mj/backends/mujoco/_added_mass"
        assert [n for n in names if n.startswith(plugin) and n.endswith(".so")]
        z.extract(library, tmp_path)
    built = ctypes.CDLL(str(tmp_path / library))
    fields, sizes = native.read_layout(built)  # the wheel's own compiled declarations
    assert (fields, sizes) == (native.FIELDS, native.SIZES)
    assert fields["State"] and sizes["Mission"] > 0
