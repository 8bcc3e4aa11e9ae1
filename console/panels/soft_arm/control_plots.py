"""The Control panel's live plots (soft arm): per-segment tracking error with task bands, and the
loop's timing, drawn from the pump's history at a rate a browser can take.

Issue 18 ("plots people read"): the curvature plot used to overlay 12 traces (target and
measured for 6 segments) whose y range followed a still arm's +-1 1/m marker noise. Now it shows
one trace per segment, the tracking error |kappa_ref - kappa_meas| (1/m), over a y range of at
least :data:`MIN_ERROR_RANGE` (a still arm's noise stays near the bottom; a real error grows the
range), with grey bands where a grasp-and-place task runs. Its legend is 7 short labels.

Issue 15 (a still console costs viewers ~nothing): each redraw re-sends a plot whole (~1.5-4 KB
to every viewer), so the error plot is redrawn only when a target moved or the measured
curvature, averaged over the last ``MEAS_AVERAGE_S`` (the simulator's noise then stays well
inside ``MEAS_BAND``), moved; the loop-timing plot (0..``axis_top`` ms) only when the period
or tick work, averaged the same way, moved a visible amount (``PlotPacer``). Both pause while
nothing moves (issue 29: a still console costs viewers nothing).
"""

from __future__ import annotations

import collections
import math
import time
import warnings
from typing import Any

import numpy as np
from viser import uplot

from console.panels.common.plot_data import PlotPacer, axis_top, thin

SEGMENT_COLORS = ("#1c7ed6", "#e8590c", "#2f9e44", "#ae3ec9", "#f08c00", "#0c8599")
BAND_COLOR = "rgba(134, 142, 150, 0.18)"
TASK_PHASES = ("settling", "planning", "approach", "grasp", "move_to_bin", "release")
# The error plot has N + 2 series, which viser sends as float64: 60 points, at most 2 Hz.
ERROR_PLOT_POINTS = 60
ERROR_PLOT_HZ = 2.0
MIN_ERROR_RANGE = 5.0  # 1/m: the error axis spans at least 0..5 (a still arm's noise: <= 1)
PLOT_BAND = 0.05  # 1/m: the error plot is redrawn when a target moved more than this,
MEAS_BAND = 1.0  # 1/m: ... or a measured curvature (averaged) more than this
MEAS_AVERAGE_S = 0.5  # s: the average (the sim's noise, <= 0.35 rms per sample, -> ~0.1)
LOOP_PLOT_HZ = 0.2  # loop timing is noise on a still arm too: at most every 5 s
LOOP_PLOT_POINTS = 60
LOOP_MIN_TOP = 20.0  # ms: the loop plot's axis spans at least 0..20 ms (period 10 ms)


def tracking_error(ref: np.ndarray, meas: np.ndarray) -> np.ndarray:
    """|kappa_ref - kappa_meas| per sample and segment (1/m); NaN where nothing was measured."""
    err = np.abs(np.asarray(ref, float) - np.asarray(meas, float))
    return np.where(np.isfinite(err), err, math.nan)


def error_range(err: np.ndarray) -> float:
    """Top of the error axis: at least MIN_ERROR_RANGE, else the largest error rounded up."""
    finite = err[np.isfinite(err)]
    top = float(finite.max()) if finite.size else 0.0
    return max(MIN_ERROR_RANGE, float(math.ceil(top * 1.1)))


class ControlPlots:
    """The tracking-error and loop-timing uPlots, and the history they are drawn from.

    Args:
        gui: Where to add the plots (the Control panel's folder).
        n_segments: Segments of the arm (one error trace each).
        history: How many samples the history keeps.
    """

    def __init__(self, gui: Any, n_segments: int, history: int) -> None:
        self.n = n_segments
        self.hist: collections.deque = collections.deque(maxlen=history)
        series = [uplot.Series(label="t (s)")]
        for i in range(n_segments):
            series.append(uplot.Series(label=f"seg {i + 1}", scale="err",
                                       stroke=SEGMENT_COLORS[i % len(SEGMENT_COLORS)], width=1.5))
        series.append(uplot.Series(label="task", scale="band", stroke="rgba(0,0,0,0)",
                                   fill=BAND_COLOR, width=0))
        self._top = MIN_ERROR_RANGE
        self.error_plot = gui.add_uplot(
            data=tuple(np.zeros(2) for _ in range(2 + n_segments)), series=tuple(series),
            scales=self._scales(), title="Tracking error |κ target − κ measured| per segment; "
                                         "grey: a task runs",
            axes=(uplot.Axis(label="t (s)"), uplot.Axis(label="error (1/m)", scale="err")),
            aspect=1.6)
        self.loop_plot = gui.add_uplot(
            data=(np.zeros(2), np.zeros(2), np.zeros(2)),
            series=(uplot.Series(label="t (s)"),
                    uplot.Series(label="period (ms)", stroke="#1c7ed6", width=2),
                    uplot.Series(label="tick work (ms)", stroke="#e8590c", width=2)),
            scales=self._loop_scales(LOOP_MIN_TOP),
            axes=(uplot.Axis(label="t (s)"), uplot.Axis(label="ms", scale="ms")),
            title="Control loop (100 Hz)", aspect=2.0)
        self._plotted: tuple[np.ndarray, np.ndarray, float] | None = None
        self._plotted_at = 0.0
        self.redraws = 0  # error plot redraws so far (the κ table follows them while disarmed)
        self._loop_pacer = PlotPacer(LOOP_PLOT_HZ)
        self._loop_top = LOOP_MIN_TOP

    @staticmethod
    def _loop_scales(top: float) -> dict[str, Any]:
        return {"x": uplot.Scale(time=False), "ms": uplot.Scale(auto=False, range=(0.0, top))}

    def _scales(self) -> dict[str, Any]:
        return {"x": uplot.Scale(time=False), "err": uplot.Scale(auto=False, range=(0.0, self._top)),
                "band": uplot.Scale(auto=False, range=(0.0, 1.0))}

    def append(self, t: float, ref: np.ndarray, meas: np.ndarray, phase: str, period_ms: float,
               work_ms: float) -> None:
        """One sample (the pump, at its rate); ``ref`` NaN where there is no target (disarmed:
        no tracking error is drawn)."""
        self.hist.append((t, np.array(ref, float), np.array(meas, float),
                          1.0 if phase in TASK_PHASES else 0.0, period_ms, work_ms))

    def draw(self, now: float | None = None) -> None:
        """Redraw what is due: the error plot at ERROR_PLOT_HZ while something moved, the loop
        plot at LOOP_PLOT_HZ."""
        hist = list(self.hist)
        if len(hist) < 2:
            return
        now = time.monotonic() if now is None else now
        t = np.array([h[0] for h in hist])
        ref = np.array([h[1] for h in hist])
        meas = np.array([h[2] for h in hist])
        recent = t >= t[-1] - MEAS_AVERAGE_S
        with np.errstate(invalid="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # a segment never measured: NaN
            meas_now = np.nanmean(meas[recent], axis=0)
        band = np.array([h[3] for h in hist])
        if (now - self._plotted_at >= 1.0 / ERROR_PLOT_HZ
                and self._moved(ref[-1], meas_now, band[-1], now)):
            err = tracking_error(ref, meas)
            top = error_range(err)
            if top != self._top:
                self._top = top
                self.error_plot.scales = self._scales()
            self.error_plot.data = thin([t, *err.T, band], ERROR_PLOT_POINTS)
            self.redraws += 1
        period = np.array([h[4] for h in hist])
        work = np.array([h[5] for h in hist])
        top = axis_top(np.concatenate([period, work]), LOOP_MIN_TOP)
        # Compared averaged like the measurement (one tick's jitter is no news; a run of late
        # ticks moves the average).
        if self._loop_pacer.due(now, (period[recent].mean(), work[recent].mean()), top):
            if top != self._loop_top:
                self._loop_top = top
                self.loop_plot.scales = self._loop_scales(top)
            self.loop_plot.data = thin((t, period, work), LOOP_PLOT_POINTS)

    def _moved(self, ref: np.ndarray, meas: np.ndarray, task: float, now: float) -> bool:
        """Whether the plot is worth redrawing: a target moved by PLOT_BAND, a measurement
        (averaged) by MEAS_BAND, or a task started or ended (its grey band). A still arm's
        noise then costs no redraw."""
        last = self._plotted
        moved = (last is None or last[0].shape != ref.shape or task != last[2]
                 or not np.allclose(ref, last[0], rtol=0.0, atol=PLOT_BAND, equal_nan=True)
                 or not np.allclose(meas, last[1], rtol=0.0, atol=MEAS_BAND, equal_nan=True))
        if moved:
            self._plotted, self._plotted_at = (ref.copy(), meas.copy(), task), now
        return moved
