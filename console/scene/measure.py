"""The measuring tool's arithmetic: where a click ray meets the table, and two points' distance.

The View panel (``console.panels.common.view``) turns a browser's next two clicks on the table into a
:class:`Measurement`; this module holds the parts worth testing against closed forms, with no
viser in it. A click that does not meet the table (a ray parallel to it, pointing away from it,
or meeting the plane z = 0 off the table's rectangle) is refused with a reason the browser is
shown; nothing is drawn for it.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import numpy.typing as npt

Table = tuple[float, float, float, float]   # x0, x1, y0, y1 (m)
MIN_SLOPE = 1e-6        # |ray direction z| / |ray direction| below this: parallel to the table


class NotOnTable(ValueError):
    """A click that does not give a point on the table (the message says why)."""


def table_hit(origin: npt.ArrayLike, direction: npt.ArrayLike,
              table: Table | None = None) -> tuple[float, float]:
    """Where the ray ``origin + t direction`` (t > 0) meets the table plane z = 0.

    Args:
        origin: The ray's start (m), e.g. the camera position of a viser click.
        direction: The ray's direction (any length but zero).
        table: The table rectangle; a point outside it is refused (None: the whole plane).

    Raises:
        NotOnTable: The ray is parallel to the table, points away from it, or meets the plane
            off the table.
    """
    o = np.asarray(origin, dtype=float).reshape(3)
    d = np.asarray(direction, dtype=float).reshape(3)
    norm = float(np.linalg.norm(d))
    if not (np.all(np.isfinite(o)) and np.all(np.isfinite(d))) or norm == 0.0:
        raise NotOnTable("the click gave no usable ray")
    if abs(d[2]) < MIN_SLOPE * norm:
        raise NotOnTable("that click runs parallel to the table; click on the table top")
    t = -o[2] / d[2]
    if t <= 0:
        raise NotOnTable("that click points away from the table; click on the table top")
    x, y = float(o[0] + t * d[0]), float(o[1] + t * d[1])
    if table is not None:
        x0, x1, y0, y1 = table
        if not (x0 <= x <= x1 and y0 <= y <= y1):
            raise NotOnTable(f"({x * 1e3:.0f}, {y * 1e3:.0f}) mm is off the table; "
                             "click on the table top")
    return x, y


@dataclasses.dataclass(frozen=True)
class Measurement:
    """Two points on the table (m) and what the view shows for them."""

    a: tuple[float, float]
    b: tuple[float, float]

    @property
    def distance(self) -> float:
        """Straight-line distance between the points (m)."""
        return math.hypot(self.b[0] - self.a[0], self.b[1] - self.a[1])

    @property
    def label(self) -> str:
        """The distance as the scene shows it: ``"123.4 mm"``."""
        return f"{self.distance * 1e3:.1f} mm"

    @property
    def midpoint(self) -> tuple[float, float]:
        return ((self.a[0] + self.b[0]) / 2, (self.a[1] + self.b[1]) / 2)

    def segment(self, z: float) -> npt.NDArray[np.float64]:
        """The line from a to b at height ``z``, as one viser line segment (1, 2, 3)."""
        return np.array([[[self.a[0], self.a[1], z], [self.b[0], self.b[1], z]]])
