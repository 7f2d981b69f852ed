"""The 2-D layer of a mission frame (PIL): where the map, the chase view and the text panel lie;
the panel (time, AoI now and so far, Jain, data, each AUV's energy and docking, the AoI colour
bar, the link legend); and what is written on the map (node and AUV labels, a scale bar).

No MuJoCo here: the renderer projects world points with `project` and hands pixels over.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import numpy as np
from numpy.typing import NDArray
from PIL import Image, ImageDraw, ImageFont

from iout_mj import palette
from iout_mj.types import FloatArray

SIDE_SHARE = 0.4
"""The column right of the map (chase view over the text panel) takes at least this share of
the frame's width."""
MIN_SIDE_PX = 64
"""A narrower column is dropped: the map fills the frame, with no text at all."""
CHASE_ASPECT = 9 / 16
"""Height / width of the chase view (at most half the frame's height)."""
MAX_FONT_PX = 36
LINE_SPACING = 1.3
FONT_DIR = Path(matplotlib.get_data_path()) / "fonts" / "ttf"
"""DejaVu Sans, shipped with matplotlib (a dependency): the same glyphs on every machine."""
PANEL_RGB = (14, 20, 30)
TEXT_RGB = (235, 235, 235)
MUTED_RGB = (170, 180, 190)
MAP_LABEL_SHARE = 1 / 36
"""Map label size as a share of the map's height (15 px on a 540 px map)."""
SCALE_BAR_SHARE = 0.2
"""The scale bar is about this share of the area's width, rounded to 1, 2 or 5 x 10^k m."""


def font(size_px: int, bold: bool = False) -> ImageFont.FreeTypeFont:
    """DejaVu Sans (bold) at `size_px` pixels per em."""
    return ImageFont.truetype(str(FONT_DIR / f"DejaVuSans{'-Bold' if bold else ''}.ttf"), size_px)


@dataclass(frozen=True)
class FrameLayout:
    """Pixel boxes of a frame: the map at the left (square, centred vertically) and right of it
    a column with the chase view over the text panel; without a column the map fills the frame."""

    width: int
    height: int
    map_w: int
    map_h: int
    map_top: int
    chase_h: int

    @property
    def side_w(self) -> int:
        """Width of the column right of the map (0: none)."""
        return self.width - self.map_w

    @property
    def panel_h(self) -> int:
        """Height of the text panel under the chase view (0: none)."""
        return self.height - self.chase_h if self.side_w else 0


def frame_layout(width: int, height: int) -> FrameLayout:
    """The layout of a `width` x `height` frame (960 x 540: a 540 px map, a 420 x 236 chase
    view, a 420 x 304 panel)."""
    side = max(width - height, math.ceil(SIDE_SHARE * width))
    if side < MIN_SIDE_PX:
        return FrameLayout(width, height, width, height, 0, 0)
    size = min(height, width - side)
    chase_h = min(round(side * CHASE_ASPECT), height // 2)
    return FrameLayout(width, height, size, size, (height - size) // 2, chase_h)


def project(
    points_m: FloatArray,
    cam_pos_m: FloatArray,
    cam_mat: FloatArray,
    fovy_deg: float,
    width: int,
    height: int,
) -> FloatArray:
    """Pixel (column, row) of world points (n, 3) in a perspective camera (MuJoCo's: it looks
    along its frame's -z, y up, `fovy_deg` the vertical field of view)."""
    local = (np.asarray(points_m) - cam_pos_m) @ np.asarray(cam_mat).reshape(3, 3)
    f = 0.5 * height / math.tan(math.radians(fovy_deg) / 2)
    depth = -local[:, 2]
    return np.stack(
        [0.5 * width + f * local[:, 0] / depth, 0.5 * height - f * local[:, 1] / depth], axis=1
    )


def nice_length_m(span_m: float) -> float:
    """The largest 1, 2 or 5 x 10^k metres not above `span_m`."""
    exp = 10.0 ** math.floor(math.log10(span_m))
    return max(m * exp for m in (1.0, 2.0, 5.0) if m * exp <= span_m)


@dataclass(frozen=True)
class PanelState:
    """What the panel shows: the mission at the end of the slot being played."""

    time_s: float
    slot: int
    horizon_slots: int
    aoi_now: float
    """Mean AoI over the nodes now (slots)."""
    aoi_so_far: float
    """Time average of the mean AoI over the slots played (the metrics' mean_aoi)."""
    jain: float
    data_mbit: float
    energy_kj: tuple[float, ...]
    docked: tuple[bool, ...]
    docked_at: tuple[int | None, ...]
    """The slot at which each AUV docked (None: not docked, or docked before rendering began)."""
    chased: int
    aoi_max: float


def worst_case(horizon_slots: int, slot_s: float, n_auvs: int, aoi_max: float) -> PanelState:
    """The widest values a mission of this size shows (to size the panel's font once)."""
    return PanelState(
        time_s=horizon_slots * slot_s,
        slot=horizon_slots,
        horizon_slots=horizon_slots,
        aoi_now=max(aoi_max, 99.9),
        aoi_so_far=max(aoi_max, 99.9),
        jain=1.0,
        data_mbit=999.9,
        energy_kj=(9999.0,) * n_auvs,
        docked=(True,) * n_auvs,
        docked_at=(horizon_slots,) * n_auvs,
        chased=n_auvs - 1,
        aoi_max=aoi_max,
    )


def badge(
    d: ImageDraw.ImageDraw, centre_px: tuple[float, float], i: int, face: ImageFont.FreeTypeFont
) -> None:
    """AUV i's tag: its number in a disc of its colour (as on the map and in the panel)."""
    rgb = palette.auv_rgb8(i)
    ink = (0, 0, 0) if sum(rgb) > 3 * 128 else (255, 255, 255)
    r = 0.62 * face.size
    u, v = centre_px
    d.ellipse(
        [u - r, v - r, u + r, v + r], fill=rgb, outline=ink, width=max(1, round(face.size) // 12)
    )
    d.text((u, v), str(i + 1), fill=ink, font=face, anchor="mm")


def _status(s: PanelState, i: int) -> str:
    if s.docked_at[i] is not None:
        return f"docked at slot {s.docked_at[i]}"
    return "docked" if s.docked[i] else "under way"


def _tick(value: float) -> str:
    return f"{value:.0f}" if value >= 10 else f"{value:.1f}"


class Panel:
    """The text panel (`width` x `height` px) at the largest font (up to MAX_FONT_PX) at which
    `sample`, the widest state, fits."""

    def __init__(self, width: int, height: int, sample: PanelState):
        self.width, self.height = width, height
        for size in range(MAX_FONT_PX, 5, -1):
            self._set_font(size)
            if self._fits(sample):
                break

    def _set_font(self, size: int) -> None:
        self.size, self.pad = size, max(2, size // 2)
        self.pitch = round(size * LINE_SPACING)
        self.font, self.bold = font(size), font(size, bold=True)

    def lines(self, s: PanelState) -> list[str]:
        """The text lines of the panel (the AUV lines follow their badges)."""
        return [
            f"\u25b2 chase view: AUV {s.chased + 1}",
            f"t = {s.time_s:.0f} s,  slot {s.slot} / {s.horizon_slots}",
            f"AoI now: {s.aoi_now:.1f} slots (node mean)",
            f"mean AoI so far: {s.aoi_so_far:.1f} (over time)",
            f"Jain {s.jain:.2f},  data {s.data_mbit:.1f} Mbit",
            *(f"AUV {i + 1}  {e:.0f} kJ,  {_status(s, i)}" for i, e in enumerate(s.energy_kj)),
            "node colour: AoI (slots), size: energy",
        ]

    def _fits(self, s: PanelState) -> bool:
        lines = self.lines(s)
        widths = [self.font.getlength(line) for line in lines]
        widths[1] = self.bold.getlength(lines[1])
        for j in range(5, 5 + len(s.energy_kj)):  # after a badge
            widths[j] += self._swatch_w()
        widest = max(*widths, self._link_legend(None, 0))
        rows = len(lines) + 2  # + the colour bar's ticks and the link legend
        tall = rows * self.pitch + self._bar_h() + 2 * self.pad
        return widest <= self.width - 2 * self.pad and tall <= self.height

    def _swatch_w(self) -> int:
        """Where an AUV's line starts, after its badge."""
        return round(1.25 * self.size) + self.pad

    def _bar_h(self) -> int:
        return max(3, round(0.7 * self.size))

    def image(self, s: PanelState) -> NDArray[np.uint8]:
        """The panel for `s` as an RGB array (height, width, 3)."""
        img = Image.new("RGB", (self.width, self.height), PANEL_RGB)
        d = ImageDraw.Draw(img)
        lines = self.lines(s)
        x, y = self.pad, self.pad
        d.text((x, y), lines[0], fill=MUTED_RGB, font=self.font)
        d.text((x, y + self.pitch), lines[1], fill=TEXT_RGB, font=self.bold)
        for j, line in enumerate(lines[2:5]):
            d.text((x, y + (j + 2) * self.pitch), line, fill=TEXT_RGB, font=self.font)
        y += 5 * self.pitch
        swatch = self._swatch_w()
        for i, line in enumerate(lines[5 : 5 + len(s.energy_kj)]):
            badge(d, (x + 0.62 * self.size, y + 0.6 * self.size), i, self.bold)
            d.text((x + swatch, y), line, fill=TEXT_RGB, font=self.font)
            y += self.pitch
        d.text((x, y), lines[-1], fill=TEXT_RGB, font=self.font)
        y = self._colour_bar(img, d, y + self.pitch, s.aoi_max)
        self._link_legend(d, y)
        return np.asarray(img)

    def _colour_bar(self, img: Image.Image, d: ImageDraw.ImageDraw, y: int, aoi_max: float) -> int:
        """The AoI ramp from 0 to A_max (older: the A_max colour) with three ticks; returns
        the y under it."""
        w, h = self.width - 2 * self.pad, self._bar_h()
        ramp = (255 * palette.aoi_rgba(np.linspace(0, 1, w))[:, :3]).astype(np.uint8)
        img.paste(Image.fromarray(np.repeat(ramp[None], h, axis=0)), (self.pad, y))
        ticks = (
            (0.0, "la", "0"),
            (0.5, "ma", _tick(aoi_max / 2)),
            (1.0, "ra", "\u2265 " + _tick(aoi_max)),
        )
        for frac, anchor, label in ticks:
            tx = self.pad + round(frac * (w - 1))
            d.line([tx, y + h, tx, y + h + 2], fill=TEXT_RGB)
            d.text((tx, y + h + 2), label, fill=TEXT_RGB, font=self.font, anchor=anchor)
        return y + h + self.pitch + 2

    def _link_legend(self, d: ImageDraw.ImageDraw | None, y: int) -> float:
        """The link colours in one row (with `d` None: only measured); returns its width."""
        x, mid = self.pad, y + self.size // 2 + 1
        seg = round(1.6 * self.size)
        for rgba, label in (
            (palette.AET_RGBA, "AET"),
            (palette.UPLINK_RGBA, "uplink"),
            (palette.FAILED_RGBA, "failed"),
        ):
            rgb = tuple(round(255 * c) for c in rgba[:3])
            if d is not None:
                d.line([x, mid, x + seg, mid], fill=rgb, width=max(2, self.size // 6))
                d.text((x + seg + self.pad // 2, y), label, fill=TEXT_RGB, font=self.font)
            x += seg + self.pad // 2 + round(self.font.getlength(label)) + self.pad * 2
        return x - self.pad * 2


class MapLabels:
    """Node indices, AUV numbers and a scale bar on a map `map_h` pixels tall."""

    def __init__(self, map_h: int):
        self.size = max(8, round(map_h * MAP_LABEL_SHARE))
        self.font, self.bold = font(self.size), font(self.size, bold=True)

    def nodes(self, d: ImageDraw.ImageDraw, centres_px: FloatArray, radii_px: FloatArray) -> None:
        """Node k's index (from 1) up and right of its disc."""
        for k, ((u, v), r) in enumerate(zip(centres_px, radii_px, strict=True)):
            off = 0.75 * r + 1
            d.text(
                (u + off, v - off),
                str(k + 1),
                fill=(255, 255, 255),
                font=self.font,
                anchor="ld",
                stroke_width=2,
                stroke_fill=(0, 0, 0),
            )

    def dock(self, d: ImageDraw.ImageDraw, below_px: FloatArray) -> None:
        """ "dock" under the dock zone's disc, whose lowest point is at `below_px`."""
        d.text(
            (below_px[0], below_px[1] + 2),
            "dock",
            fill=(255, 255, 255),
            font=self.font,
            anchor="mt",
            stroke_width=2,
            stroke_fill=(0, 0, 0),
        )

    def auvs(
        self,
        d: ImageDraw.ImageDraw,
        centres_px: FloatArray,
        yaw_rad: FloatArray,
        docked: tuple[bool, ...],
    ) -> None:
        """Each AUV under way tagged with its number in a disc of its colour, on its port side
        (clear of its heading); docked ones are listed in the panel only."""
        off = 1.3 * self.size
        for i, ((u, v), yaw) in enumerate(zip(centres_px, yaw_rad, strict=True)):
            if not docked[i]:
                badge(d, (u - off * math.sin(yaw), v - off * math.cos(yaw)), i, self.bold)

    def scale_bar(
        self,
        d: ImageDraw.ImageDraw,
        corner_px: tuple[float, float],
        px_per_m: float,
        span_m: float,
        bottom_px: float,
    ) -> None:
        """A bar of about SCALE_BAR_SHARE of `span_m` whose box's top right corner is at
        `corner_px` (moved up to end above `bottom_px`)."""
        length_m = nice_length_m(SCALE_BAR_SHARE * span_m)
        length_px = length_m * px_per_m
        label = f"{length_m:g} m"
        pad = max(2, self.size // 4)
        box_w = length_px + self.font.getlength(label) + 4 * pad
        box_h = self.size + 2 * pad
        right, top = corner_px[0], min(corner_px[1], bottom_px - box_h - 1)
        d.rectangle([right - box_w, top, right, top + box_h], fill=PANEL_RGB)
        mid, x0 = top + box_h / 2, right - box_w + pad
        white = (255, 255, 255)
        d.line([x0, mid, x0 + length_px, mid], fill=white, width=3)
        for end in (x0, x0 + length_px):
            d.line([end, mid - pad - 1, end, mid + pad + 1], fill=white, width=2)
        d.text((x0 + length_px + 2 * pad, mid), label, fill=white, font=self.font, anchor="lm")
