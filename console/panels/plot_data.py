"""Plot columns thinned for the wire: a live uPlot is re-sent whole on every update, so its
cost per viewer is (points x series x bytes) times the update rate.

At most :data:`PLOT_POINTS` evenly spaced samples (the newest always kept): ~100 points is
what a 300 px wide panel shows. Returned as float32 (7 digits are more than a plot resolves),
though viser 1.1.1 sends a uPlot's columns as float64 (8 bytes a value) whatever they are.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import numpy.typing as npt

PLOT_POINTS = 100


def thin(columns: Sequence[npt.ArrayLike], max_points: int = PLOT_POINTS,
         ) -> tuple[npt.NDArray[np.float32], ...]:
    """``columns`` (equal lengths) at no more than ``max_points`` samples, newest kept, float32."""
    if max_points < 2:
        raise ValueError(f"max_points must be >= 2, got {max_points}")
    cols = [np.asarray(c, dtype=float) for c in columns]
    n = len(cols[0]) if cols else 0
    if any(len(c) != n for c in cols):
        raise ValueError("plot columns must have equal lengths")
    if n <= max_points:
        keep = np.arange(n)
    else:  # evenly spaced from the newest backwards, so the kept samples do not flicker
        step = int(np.ceil(n / max_points))
        keep = np.arange(n - 1, -1, -step)[::-1]
    return tuple(c[keep].astype(np.float32) for c in cols)
