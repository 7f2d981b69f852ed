"""Site-specific transmission loss: a table TL(frequency, receiver depth, horizontal range) for
one source depth, precomputed by BELLHOP for a sound-speed profile over a flat seabed, saved as
an .npz file (plain arrays, never pickle), and its bilinear interpolation in range and depth
(compiled: `iout_tl_interpolate` in world/network.c).

The table stands where the link budget's spreading and absorption stand, TL = k_s 10 log10(d)
+ alpha(f) d / 1000 (`acoustics.transmission_loss_db`). A node lies on the flat seabed, so the
table's source is the node (`source_depth_m`, just above the seabed) and its receivers are the
AUVs at their depths; by reciprocity the same TL serves the AET (AUV to node) and the uplink
(node to AUV).

BELLHOP runs in process through the optional `pelagic` package (`pip install -e .[bellhop]`;
Huang, pelagic 0.5: BELLHOP and KRAKEN checked against the Acoustics Toolbox 2023.5; Porter,
"The BELLHOP manual and user's guide", 2011): incoherent transmission loss (smooth in range,
as a link budget wants), a vacuum surface, Thorp volume attenuation, and a sand half-space
below (c_p 1650 m/s, 1.9 g/cm^3, 0.8 dB per wavelength: Jensen, Kuperman, Porter and Schmidt,
Computational Ocean Acoustics, 2nd ed. 2011, Table 1.3).
"""

from __future__ import annotations

import csv
import functools
import io
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from iout_mj import native
from iout_mj.config import AcousticsConfig, ChannelConfig
from iout_mj.errors import IoutError
from iout_mj.files import write_atomic
from iout_mj.types import FloatArray
from iout_mj.world import acoustics  # a module: acoustics.LinkBudget loads tables from here

TABLE_ARRAYS = ("frequency_khz", "depth_m", "range_m", "tl_db", "source_depth_m")
"""The arrays of a table file, and nothing else."""
SAND_BOTTOM = {"type": "halfspace", "cp": 1650.0, "rho": 1.9, "ap": 0.8}
"""The seabed below the water (Jensen et al. 2011, Table 1.3, sand)."""
SEABED_CLEARANCE_M = 0.5
"""The source (a node on the seabed) and the deepest receiver sit this far above the seabed:
BELLHOP needs them inside the water column."""


class TLTableError(IoutError, ValueError):
    """A transmission-loss table (or its file, or a sound-speed profile) is malformed; the
    message names what is wrong and what is accepted."""


def _axis(name: str, values: ArrayLike) -> FloatArray:
    axis = np.asarray(values, dtype=float)
    if axis.ndim != 1 or axis.size < 1:
        raise TLTableError(f"{name} has shape {axis.shape}: accepted a 1-D axis of >= 1 value")
    if not np.all(np.isfinite(axis)) or np.any(axis < 0):
        raise TLTableError(f"{name} holds {axis.tolist()}: accepted finite values >= 0")
    if np.any(np.diff(axis) <= 0):
        raise TLTableError(f"{name} is {axis.tolist()}: accepted strictly increasing values")
    return axis


@dataclass(frozen=True)
class TLTable:
    """TL in dB (F, D, R) at each frequency (kHz), receiver depth and horizontal range (m), for
    a source at `source_depth_m`. Checked when made: axes strictly increasing and >= 0, TL
    finite, of the axes' shape."""

    frequency_khz: FloatArray
    depth_m: FloatArray
    range_m: FloatArray
    tl_db: FloatArray
    source_depth_m: float

    def __post_init__(self) -> None:
        for name in ("frequency_khz", "depth_m", "range_m"):
            object.__setattr__(self, name, _axis(name, getattr(self, name)))
        tl = np.ascontiguousarray(self.tl_db, dtype=float)
        shape = (self.frequency_khz.size, self.depth_m.size, self.range_m.size)
        if tl.shape != shape:
            raise TLTableError(
                f"tl_db has shape {tl.shape}: accepted (frequencies, depths, ranges) = {shape}"
            )
        bad = np.argwhere(~np.isfinite(tl))
        if bad.size:
            f, d, r = bad[0]
            raise TLTableError(
                f"tl_db is {tl[f, d, r]} at {self.frequency_khz[f]:g} kHz, depth "
                f"{self.depth_m[d]:g} m, range {self.range_m[r]:g} m ({len(bad)} such values): "
                "accepted finite dB (start the range axis above 0 m and keep the depths "
                "inside the water column)"
            )
        object.__setattr__(self, "tl_db", tl)
        depth = float(self.source_depth_m)
        if not (math.isfinite(depth) and depth >= 0):
            raise TLTableError(f"source_depth_m is {depth}: accepted a finite depth >= 0 m")
        object.__setattr__(self, "source_depth_m", depth)

    def band(self, frequency_khz: float) -> FloatArray:
        """The (D, R) TL of one of the table's frequencies (within 1 Hz)."""
        hit = np.flatnonzero(np.abs(self.frequency_khz - frequency_khz) <= 1e-3)
        if not hit.size:
            raise TLTableError(
                f"no TL at {frequency_khz:g} kHz in the table: accepted one of "
                f"{self.frequency_khz.tolist()} kHz"
            )
        return self.tl_db[hit[0]]

    def interpolate_db(
        self, frequency_khz: float, range_m: ArrayLike, depth_m: ArrayLike
    ) -> FloatArray:
        """TL (dB) at horizontal ranges and receiver depths (broadcast together), bilinear in
        range and depth, clamped to the table's edges; the compiled `iout_tl_interpolate`."""
        r, z = np.broadcast_arrays(np.asarray(range_m, float), np.asarray(depth_m, float))
        r, z = np.ascontiguousarray(r, dtype=float), np.ascontiguousarray(z, dtype=float)
        out = np.empty(r.shape)
        band = np.ascontiguousarray(self.band(frequency_khz))
        native.call(
            native.lib.iout_tl_interpolate,
            native.address(self.range_m),
            self.range_m.size,
            native.address(self.depth_m),
            self.depth_m.size,
            native.address(band),
            native.address(r),
            native.address(z),
            r.size,
            native.address(out),
        )
        return out


def save_table(table: TLTable, path: Path) -> None:
    """The table as an .npz of plain float arrays (TABLE_ARRAYS), replaced whole."""
    buffer = io.BytesIO()
    arrays: dict[str, Any] = {n: np.asarray(getattr(table, n), float) for n in TABLE_ARRAYS}
    np.savez(buffer, **arrays)
    write_atomic(Path(path), buffer.getvalue())


def load_table(path: Path) -> TLTable:
    """A table written by `save_table`, checked (`TLTable`); raises TLTableError naming the
    file and what is wrong."""
    try:
        with np.load(Path(path), allow_pickle=False) as data:
            arrays = {name: data[name] for name in data.files}
    except (OSError, ValueError, EOFError) as exc:
        raise TLTableError(f"{path}: not a readable .npz transmission-loss table ({exc})") from exc
    if set(arrays) != set(TABLE_ARRAYS):
        raise TLTableError(
            f"{path} holds the arrays {sorted(arrays)}: accepted exactly {list(TABLE_ARRAYS)}"
        )
    if np.asarray(arrays["source_depth_m"]).size != 1:
        raise TLTableError(f"{path}: source_depth_m holds several values: accepted one depth")
    try:
        return TLTable(**{**arrays, "source_depth_m": float(arrays["source_depth_m"])})
    except TLTableError as exc:
        raise TLTableError(f"{path}: {exc}") from exc


@functools.lru_cache(maxsize=8)
def _load_cached(path: str, mtime_ns: int, size: int) -> TLTable:
    return load_table(Path(path))


def load_table_cached(path: str | Path) -> TLTable:
    """`load_table`, read once per file version (its path, modification time and size): every
    env of a run builds its link budget from the same file."""
    try:
        info = Path(path).stat()
    except OSError as exc:
        raise TLTableError(
            f"transmission_loss_file {path}: cannot read it ({exc.strerror or exc}); accepted "
            "an .npz table written by `iout-mj tl-table`"
        ) from exc
    return _load_cached(str(path), info.st_mtime_ns, info.st_size)


DEPTH_TOLERANCE_M = 1e-3
"""How far the table's source may sit from the nodes' (seabed - SEABED_CLEARANCE_M)."""
LINK_TABLE_FIELDS = ("tl_range_m", "tl_depth_m", "tl_wet_db", "tl_data_db")
"""The Link record's table arrays (native.h's IOUT_LINK_ARRAYS)."""


def link_bounds() -> dict[str, int]:
    """The compiled link constants' room for a table: ranges, depths and cells (depths x
    ranges) of one frequency (native.h's IOUT_TL_MAX_*)."""
    shapes = {f: acoustics.LINK_DTYPE[f].shape[0] for f in LINK_TABLE_FIELDS}
    return {
        "ranges": shapes["tl_range_m"],
        "depths": shapes["tl_depth_m"],
        "cells": shapes["tl_wet_db"],
    }


def check_link_table(table: TLTable, cfg: AcousticsConfig, channel: ChannelConfig) -> None:
    """Refuse a table the link budget cannot use: larger than the compiled link constants,
    without the AET or data frequency, its source not at the nodes' depth, or AUV depths
    outside its depth axis (TLTableError naming what is accepted)."""
    bounds = link_bounds()
    d, r = table.depth_m.size, table.range_m.size
    if d > bounds["depths"] or r > bounds["ranges"] or d * r > bounds["cells"]:
        raise TLTableError(
            f"a table of {d} depths x {r} ranges: accepted at most {bounds['depths']} depths, "
            f"{bounds['ranges']} ranges and {bounds['cells']} depths x ranges (a coarser "
            "`iout-mj tl-table --range-step-m`)"
        )
    for name in ("f_wet_khz", "f_data_khz"):
        f = getattr(cfg, name)
        if not np.any(np.abs(table.frequency_khz - f) <= 1e-3):
            raise TLTableError(
                f"acoustics.{name} is {f:g} kHz, not in the table: accepted a table holding "
                f"both link frequencies (it holds {table.frequency_khz.tolist()} kHz)"
            )
    auv_m = channel.auv_depths_m or (channel.auv_depth_m,)
    seabeds = sorted(set(channel.node_depths_m or (channel.node_depth_m,)))
    source = table.source_depth_m + SEABED_CLEARANCE_M
    if any(abs(z - source) > DEPTH_TOLERANCE_M for z in seabeds):
        raise TLTableError(
            f"the table's source (a node) lies at {table.source_depth_m:g} m, for a seabed at "
            f"{source:g} m; the channel's nodes lie on seabeds at {seabeds} m: accepted a "
            f"table made for them (`iout-mj tl-table` puts the source "
            f"{SEABED_CLEARANCE_M:g} m above the seabed of channel.node_depth_m)"
        )
    top, bottom = float(table.depth_m[0]), float(table.depth_m[-1])
    outside = sorted({z for z in auv_m if not top <= z <= bottom})
    if outside:
        raise TLTableError(
            f"AUV depths {outside} m lie outside the table's depths: accepted AUV depths from "
            f"{top:g} to {bottom:g} m"
        )


def link_values(cfg: AcousticsConfig, channel: ChannelConfig | None) -> dict[str, Any]:
    """The Link record's table fields: the channel's transmission_loss_file, checked
    (`check_link_table`), at the AET and data frequencies; none (tl_ranges 0: spreading and
    absorption) without one."""
    none = {"tl_ranges": 0, "tl_depths": 0, **{f: 0.0 for f in LINK_TABLE_FIELDS}}
    if channel is None or channel.transmission_loss_file is None:
        return none
    path = channel.transmission_loss_file
    table = load_table_cached(path)
    try:
        check_link_table(table, cfg, channel)
    except TLTableError as exc:
        raise TLTableError(f"transmission_loss_file {path}: {exc}") from exc
    cells = table.depth_m.size * table.range_m.size
    values: dict[str, Any] = {
        "tl_ranges": table.range_m.size,
        "tl_depths": table.depth_m.size,
        "tl_range_m": _padded(table.range_m, link_bounds()["ranges"]),
        "tl_depth_m": _padded(table.depth_m, link_bounds()["depths"]),
    }
    for name, f in (("tl_wet_db", cfg.f_wet_khz), ("tl_data_db", cfg.f_data_khz)):
        values[name] = _padded(table.band(f).reshape(cells), link_bounds()["cells"])
    return values


def _padded(values: FloatArray, size: int) -> FloatArray:
    out = np.zeros(size)
    out[: values.size] = values
    return out


def read_profile(path: Path) -> tuple[FloatArray, FloatArray]:
    """A sound-speed profile CSV: one 'depth_m, c_mps' per row (a header row is allowed),
    depths strictly increasing from the surface, speeds from 1400 to 1650 m/s."""
    try:
        rows = list(csv.reader(Path(path).read_text().splitlines()))
    except (OSError, UnicodeDecodeError) as exc:
        raise TLTableError(f"{path}: cannot read the sound-speed profile ({exc})") from exc
    rows = [r for r in rows if r and any(c.strip() for c in r)]
    if rows and not _numeric(rows[0]):
        rows = rows[1:]
    if len(rows) < 2 or not all(len(r) == 2 and _numeric(r) for r in rows):
        raise TLTableError(
            f"{path}: accepted at least two rows of 'depth_m, c_mps' numbers (a header row "
            "is allowed)"
        )
    depth, speed = np.array([[float(c) for c in r] for r in rows]).T
    _axis(f"{path}: depth_m", depth)
    if not np.all((speed >= 1400.0) & (speed <= 1650.0)):
        raise TLTableError(f"{path}: c_mps {speed.tolist()}: accepted 1400 to 1650 m/s")
    return depth, speed


def _numeric(row: Sequence[str]) -> bool:
    try:
        [float(c) for c in row]
    except ValueError:
        return False
    return True


def mackenzie_profile(channel: ChannelConfig, seabed_m: float, points: int = 11) -> list:
    """[[depth, c], ...] from the surface to the seabed at the channel's temperature and
    salinity (Mackenzie 1981; isothermal, isohaline water)."""
    z = np.linspace(0.0, seabed_m, points)
    c = acoustics.mackenzie_sound_speed_mps(channel.temperature_degc, channel.salinity_ppt, z)
    return np.column_stack([z, c]).tolist()


TL_CAP_DB = 200.0
"""TL given where no ray reaches (a shadow zone, or a receiver beyond the beams' span): no link
(10^-20 of the power), finite so that the table interpolates."""
BEAM_ANGLES = {"from": -89.0, "to": 89.0, "count": 2000}
"""Launch angles (degrees) of BELLHOP's beams: every direction but the horizontal's grazing
extremes."""


def bellhop_case(
    profile: list,
    seabed_m: float,
    source_m: float,
    frequency_khz: float,
    depths_m: FloatArray,
    ranges_m: FloatArray,
) -> dict[str, Any]:
    """pelagic's BELLHOP case (its JSON contract, version 2) of one frequency: incoherent TL
    at the receivers depths_m x ranges_m (evenly spaced ranges), flat seabed at seabed_m."""
    return {
        "pelagic": 2,
        "model": "bellhop",
        "title": f"iout-mj TL table, {frequency_khz:g} kHz",
        "frequency": frequency_khz * 1e3,
        "interpolation": "c_linear",
        "attenuation": {"volume": "thorp"},
        "media": [{"to": seabed_m, "ssp": profile}],
        "surface": "vacuum",
        "bottom": SAND_BOTTOM,
        "source": {"depth": [source_m]},
        "receivers": {
            "depth": depths_m.tolist(),
            "range": {
                "from": float(ranges_m[0]),
                "to": float(ranges_m[-1]),
                "count": int(ranges_m.size),
                "unit": "m",
            },
        },
        "bellhop": {
            "run": "incoherent",
            "beam": "geometric_hat_cartesian",
            "angles": BEAM_ANGLES,
            "box": {"depth": 1.1 * seabed_m, "range": 1.1 * float(ranges_m[-1])},
        },
    }


def compute_table(
    channel: ChannelConfig,
    frequencies_khz: Sequence[float],
    max_range_m: float = 1500.0,
    range_step_m: float = 10.0,
    depth_points: int = 21,
    profile_csv: Path | None = None,
) -> TLTable:
    """BELLHOP's TL over horizontal range (range_step_m to max_range_m) and receiver depth
    (1 m to the seabed) for a node on a flat seabed at the channel's node_depth_m, in a
    Mackenzie profile of the channel's temperature and salinity or a CSV profile
    (`read_profile`, reaching the seabed); TL_CAP_DB where no ray arrives. Needs `pelagic`
    (`pip install -e .[bellhop]`)."""
    try:
        import pelagic
    except ImportError as exc:
        raise TLTableError(
            "computing a TL table needs BELLHOP through the optional package pelagic: accepted "
            "after `pip install -e .[bellhop]`"
        ) from exc
    seabed = float(channel.node_depth_m)
    if profile_csv is None:
        profile = mackenzie_profile(channel, seabed)
    else:
        z, c = read_profile(profile_csv)
        if z[0] > 0 or z[-1] < seabed:
            raise TLTableError(
                f"{profile_csv} spans {z[0]:g} to {z[-1]:g} m: accepted a profile from the "
                f"surface (0 m) to the seabed ({seabed:g} m) or deeper"
            )
        keep = z < seabed
        profile = [
            *np.column_stack([z[keep], c[keep]]).tolist(),
            [seabed, float(np.interp(seabed, z, c))],
        ]
    source = seabed - SEABED_CLEARANCE_M
    depths = np.linspace(1.0, source, depth_points)
    ranges = np.arange(range_step_m, max_range_m + 0.5 * range_step_m, range_step_m)
    freqs = sorted({float(f) for f in frequencies_khz})
    bands = []
    for f in freqs:
        case = pelagic.bellhop.Case.from_dict(
            bellhop_case(profile, seabed, source, f, depths, ranges)
        )
        tl = np.asarray(case.run().field.transmission_loss(), dtype=float)[0]
        bands.append(np.where(np.isfinite(tl), np.minimum(tl, TL_CAP_DB), TL_CAP_DB))
    return TLTable(np.asarray(freqs), depths, ranges, np.stack(bands), source)
