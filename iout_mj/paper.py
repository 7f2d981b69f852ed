"""Numbers the paper leaves open, as the authors' public code sets them (DESIGN.md section 4)."""

from __future__ import annotations

Point = tuple[float, float]

# Node layouts of the authors' public code (DESIGN.md section 4), metres.
PAPER_LAYOUTS: dict[int, tuple[Point, ...]] = {
    7: ((100, 100), (800, 500), (500, 900), (300, 700), (500, 200), (900, 200), (200, 400)),
    13: (
        (100, 100),
        (800, 500),
        (500, 900),
        (300, 700),
        (200, 400),
        (900, 200),
        (500, 200),
        (700, 800),
        (800, 200),
        (700, 300),
        (700, 100),
        (300, 100),
        (900, 700),
    ),
}
# Start positions: the first two from the authors' code, the others continue the pattern.
DEFAULT_STARTS: tuple[Point, ...] = ((50, 50), (50, 150), (150, 50), (150, 150))
