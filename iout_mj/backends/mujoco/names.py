"""Names of MJCF files and elements, in one place (task code uses these, never literals)."""

from pathlib import Path


def _assets_dir() -> Path:
    """`iout_mj/assets` in an installed wheel (the build maps the top-level `assets/` there),
    else the checkout's top-level `assets/` (source tree, editable install)."""
    package = Path(__file__).resolve().parents[2]
    installed = package / "assets"
    return installed if installed.is_dir() else package.parent / "assets"


ASSETS_DIR = _assets_dir()
AUV_XML = ASSETS_DIR / "auv.xml"
ARENA_XML = ASSETS_DIR / "arena.xml"

# Elements of assets/auv.xml (each AUV copy carries the prefix auv_prefix(i)).
AUV_BODY = "auv"
JOINT_X, JOINT_Y, JOINT_YAW = "x", "y", "yaw"
THRUST = "thrust"
YAW_ACTUATOR = "yaw_torque"
HULL_DRAG_GEOM = "hull_drag"
FIN_DRAG_GEOM = "fin_drag"
PROPELLER_SITE = "propeller"
IMU_SITE = "imu"
CHASE_CAMERA = "chase"

# Elements added by vehicle.build_scene.
TOP_CAMERA = "top"
DOCK_GEOM = "dock_zone"
SEABED_GEOM = "seabed"


def auv_prefix(i: int) -> str:
    """Name prefix of AUV i's elements."""
    return f"auv{i}/"


def node_name(k: int) -> str:
    """Name of node k's body."""
    return f"node{k}"
