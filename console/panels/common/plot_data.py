"""Live plots cheap on the wire: a uPlot is re-sent whole on every update, so its cost per
viewer is (points x series x bytes) times the update rate; both are cut here.

:func:`thin`: at most :data:`PLOT_POINTS` evenly spaced samples (the newest always kept): ~100
points is what a 300 px wide panel shows. Returned as float32 (7 digits are more than a plot
resolves), though viser 1.1.1 sends a uPlot's columns as float64 (8 bytes a value) whatever
they are, uncompressed.

:class:`PlotPacer`: when a plot is worth re-sending at all, a dead band on what a person could
see change (a fraction of the y axis, :func:`axis_top`), at most ``max_hz`` while it changes;
it pauses while nothing visibly changes (issue 29: a still console costs viewers nothing; its
next redraw shows the whole history again). viser does not tell the server which tab or folder a
browser has open (and each viewer may have another one open), so a plot is paced, never
skipped for being hidden.
"""

from __future__ import annotations

import math
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


def axis_top(values: npt.ArrayLike, minimum: float) -> float:
    """Top of a y axis from 0 that holds ``values`` with 10 % headroom: at least ``minimum``,
    else the next 1-2-5 step (so the axis, and what counts as a visible change, stays put while
    the values wander)."""
    v = np.asarray(values, dtype=float)
    finite = v[np.isfinite(v)]
    top = 1.1 * float(finite.max()) if finite.size else 0.0
    if top <= minimum:
        return float(minimum)
    decade = 10.0 ** math.floor(math.log10(top))
    return float(next(k * decade for k in (1.0, 2.0, 5.0, 10.0) if k * decade >= top))


class PlotPacer:
    """When a live plot is worth re-sending to every viewer: only what a person could see change.

    :meth:`due` is true when the newest values moved by more than ``visible`` of the y axis
    (0.03: ~4 px of a 150 px plot) since the values last sent, or the axis changed; at most
    ``max_hz`` times a second while they keep moving (a batch of new samples each time). While
    nothing visibly changes the plot pauses. Pure: the caller passes the time.

    Args:
        max_hz: Largest redraw rate while the plot changes.
        visible: Smallest change that counts, as a fraction of the axis top.
    """

    def __init__(self, max_hz: float = 2.0, visible: float = 0.03) -> None:
        if max_hz <= 0 or visible < 0:
            raise ValueError("max_hz must be > 0 and visible >= 0")
        self.max_hz, self.visible = max_hz, visible
        self._shown: npt.NDArray[np.float64] | None = None
        self._top = math.nan
        self._at = -math.inf

    def due(self, now: float, newest: npt.ArrayLike, top: float) -> bool:
        """Whether to redraw at ``now`` with ``newest`` (one value per series, NaN for none)
        on an axis from 0 to ``top``; a True answer counts as sent."""
        new = np.asarray(newest, dtype=float).ravel()
        if now - self._at < 1.0 / self.max_hz:
            return False
        last = self._shown
        changed = (last is None or last.shape != new.shape or top != self._top
                   or not np.allclose(new, last, rtol=0.0, atol=self.visible * top,
                                      equal_nan=True))
        if changed:
            self._shown, self._top, self._at = new.copy(), top, now
        return changed
