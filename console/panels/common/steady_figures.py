"""Figures people read on a live panel that change only when the change means something.

A measured figure (a link's round trip p99, a loop's tick work) jitters on every read and a
counter (messages sent, ticks) grows on every read; each new text is re-sent whole to every
viewer, so a still console showing them would cost each viewer a message every refresh
(issue 29: a still console costs nothing). :class:`SteadyFigure` shows a measurement that
follows the value only past a band; :class:`CountRate` turns an ever-growing counter into its
rate, which a steady link or loop keeps. Pure: the caller passes the time.
"""

from __future__ import annotations

import collections
import math

# A round trip as shown follows the measured one past 25 % and 0.1 ms: a steady link's p99
# jitters by less (the Hardware readout and the soft arm's link line).
RTT_BAND = (0.25, 0.1)


class SteadyFigure:
    """A measured figure as shown: it follows the value only once that moved past a band.

    Args:
        rel: Smallest change that counts, as a fraction of the shown value.
        floor: ... and never less than this (the figure's unit), so values near 0 do not
            flicker.
    """

    def __init__(self, rel: float = 0.2, floor: float = 0.0) -> None:
        if rel < 0 or floor < 0:
            raise ValueError("rel and floor must be >= 0")
        self.rel, self.floor = rel, floor
        self._shown: float | None = None

    def shown(self, value: float | None) -> float | None:
        """The figure to show for the newest ``value`` (None or NaN: nothing measured, shown
        as such at once)."""
        if value is None or not math.isfinite(value):
            self._shown = None
            return None
        last = self._shown
        if last is None or abs(value - last) > max(self.floor, self.rel * abs(last)):
            self._shown = float(value)
        return self._shown


class CountRate:
    """Events per second of an ever-growing counter, over at least ``window_s`` of reads.

    Args:
        window_s: Shortest span the rate is measured over (a 100 Hz counter read at 4 Hz
            counts 25 +- 1 a read: over 2 s the rate is within 2 %).
    """

    def __init__(self, window_s: float = 2.0) -> None:
        if window_s <= 0:
            raise ValueError("window_s must be > 0")
        self.window_s = window_s
        self._reads: collections.deque[tuple[float, int]] = collections.deque()

    def rate(self, now: float, count: int) -> float | None:
        """The rate at ``now`` with the counter at ``count``; None until reads span
        ``window_s``. A counter that went back (a new link) starts afresh."""
        reads = self._reads
        if reads and (count < reads[-1][1] or now < reads[-1][0]):
            reads.clear()
        reads.append((now, count))
        while len(reads) > 2 and now - reads[1][0] >= self.window_s:
            reads.popleft()
        t0, c0 = reads[0]
        if now - t0 < self.window_s:
            return None
        return (count - c0) / (now - t0)
