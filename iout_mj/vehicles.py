"""The vehicles `physics.vehicle` selects: each one's MJCF file and constants (no MuJoCo here).

`paper-torpedo` (the default): assets/auv.xml, the 3 m torpedo whose surge drag is calibrated
to the config's rho C_d S / 2 (see iout_mj/backends/mujoco/vehicle.py).

`remus100`: assets/remus100.xml, the REMUS 100 of T. Prestero (2001), "Verification of a
six-degree of freedom simulation model for the REMUS autonomous underwater vehicle", S.M.
thesis, MIT/WHOI (P below), with Fossen's MSS model (github cybergalactic/MSS,
VESSELS/remus100.m; MSS below) as the cross-check. Its hull drag is its own, not the config's:
- surge drag |X_uu| v^2, X_uu = -1.62 kg/m (P Appendix B);
- propeller thrust 3.86 N at 1500 rpm (P Table C.9), steady speed 1.54 m/s (P Table 8.1);
- rho = 1030 kg/m^3 (P's sea water), wetted area 0.709 m^2 (P Table A.1): the cubic model
  fitted to the hull's own steady drag has C_d = 2 |X_uu| / (rho S) = 0.004437;
- V_max 2.5 m/s: MSS's maximum speed (remus100.m header, 1525 rpm);
- mass 30.48 kg (P Table 2.3, W = 299 N) + surge added mass 0.93 kg (P Appendix B, X_udot).
MSS's drag is another estimate: Cd = 0.42 on the frontal area pi (0.19/2)^2 at rho 1026
(remus100.m, "from Allen et al. (2000)"), i.e. 6.13 kg/m, 3.8 times P's X_uu.

Both hulls carry their full planar added mass (surge, sway, yaw, the sway-yaw coupling, the
Munk terms) through the iout.added_mass MuJoCo plugin (iout_mj/backends/mujoco/added_mass.c);
the REMUS's plugin also applies P's cross-flow drag (Y_vv, Y_rr, N_vv) and the body's lift
(the MJCF derives its share of P's Y_uv and N_uv).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from iout_mj.schema import ConfigError


@dataclass(frozen=True)
class Vehicle:
    """A hull the MuJoCo backend can fly, and what the rest of the project needs of it."""

    name: str
    mjcf: str
    """File name in the assets folder; its elements carry the names of `names.py`."""
    summary: str
    mass_kg: float
    """Rigid plus surge added mass (the MJCF's body mass)."""
    length_m: float
    thrust_gain_nspm: float
    """k_v of the surge speed servo: 2 /s times the mass for both hulls."""
    hull_drag_nspm2: float | None = None
    """Steady surge drag / v^2 of the hull, N s^2/m^2; None: the config's rho C_d S / 2."""
    motion: MappingProxyType[str, Any] = field(default_factory=lambda: MappingProxyType({}))
    """MotionConfig values this vehicle implies (`physics.vehicle` in a config file sets them
    unless the file sets them itself)."""


PAPER_TORPEDO = Vehicle(
    name="paper-torpedo",
    mjcf="auv.xml",
    summary="3 m x 0.32 m torpedo, drag calibrated to the paper's C_d S (the default)",
    mass_kg=247.3,
    length_m=3.0,
    thrust_gain_nspm=500.0,
)

REMUS_X_UU_KGPM = 1.62
"""|X_uu|, P Appendix B."""
REMUS_RHO_KGPM3 = 1030.0
REMUS_WETTED_AREA_M2 = 0.709
"""P Table A.1."""

REMUS100 = Vehicle(
    name="remus100",
    mjcf="remus100.xml",
    summary="REMUS 100 from Prestero (2001): 1.33 m x 0.191 m, 31 kg, V_max 2.5 m/s (MSS)",
    mass_kg=31.41,
    length_m=1.33,
    thrust_gain_nspm=63.5,
    hull_drag_nspm2=REMUS_X_UU_KGPM,
    motion=MappingProxyType(
        {
            "v_max_mps": 2.5,
            "water_density_kgpm3": REMUS_RHO_KGPM3,
            "wetted_area_m2": REMUS_WETTED_AREA_M2,
            "drag_coefficient": 2 * REMUS_X_UU_KGPM / (REMUS_RHO_KGPM3 * REMUS_WETTED_AREA_M2),
        }
    ),
)

VEHICLES: dict[str, Vehicle] = {v.name: v for v in (PAPER_TORPEDO, REMUS100)}
DEFAULT = PAPER_TORPEDO.name


def get(name: str) -> Vehicle:
    """The vehicle called `name`; a ConfigError names the accepted ones."""
    try:
        return VEHICLES[name]
    except (KeyError, TypeError):
        raise ConfigError(
            f"vehicle={name!r} is unknown: accepted {', '.join(sorted(VEHICLES))}"
        ) from None


def hull_drag_nspm2(name: str, config_drag_nspm2: float) -> float:
    """Steady surge drag / v^2 of the MuJoCo hull: the vehicle's own, or the config's."""
    own = get(name).hull_drag_nspm2
    return config_drag_nspm2 if own is None else own
