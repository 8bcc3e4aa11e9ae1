"""What the Repeatability panel shows: open versus closed loop in Table I's terms, and a plot.

Kept apart from the panel (widgets, worker thread) so the numbers and their rendering are plain
functions of the measured tips. A :class:`Comparison` holds what a run has measured so far (N moves
open loop to a point, then N closed loop); :func:`comparison_html` turns it into the table (mean
tip error and +- spread in mm, one row per loop, beside Table I's hardware figures for one and
two segments) and :func:`error_plot_svg` into a per-move scatter of the tip error, open loop
against closed loop. Every value cell carries ``data-testid`` and its value in ``data-mm`` (the
browser test reads them).
"""

from __future__ import annotations

import dataclasses
import html
import math
from typing import Literal

import numpy as np
import numpy.typing as npt

from core.control.repeatability import TABLE_I_MM
from core.units import fmt_mm

Array = npt.NDArray[np.float64]
Loop = Literal["open", "closed"]
_AXES = ("x", "y", "z")
COLOURS: dict[Loop, str] = {"open": "#e8590c", "closed": "#1c7ed6"}
LABELS: dict[Loop, str] = {"open": "open loop", "closed": "closed loop on the tip"}


@dataclasses.dataclass(frozen=True)
class RepeatabilityResult:
    """Tips reached (k, 3) for a point; ``message`` says why fewer than asked, if so."""

    point: Array
    tips: Array
    requested: int
    message: str = ""
    source: str = "encoders"  # what measured the tips: "encoders" | "tip sensor"
    closed_loop: bool = False
    seconds: float = 0.0  # how long the run took (retracts included)
    corrections: int = 0  # closed-loop correction moves, all repetitions together

    @property
    def mean(self) -> Array:
        return self.tips.mean(axis=0)

    @property
    def spread(self) -> Array:
        """Per axis +-(max - min) / 2 (m), Table I's "+-"."""
        return 0.5 * np.ptp(self.tips, axis=0)

    @property
    def std(self) -> Array:
        return self.tips.std(axis=0, ddof=1) if len(self.tips) > 1 else np.zeros(3)

    @property
    def offset(self) -> Array:
        """Mean reached tip minus the point (m)."""
        return self.mean - self.point

    @property
    def errors(self) -> Array:
        """Distance of every reached tip to the point (k,), m."""
        return np.linalg.norm(self.tips - self.point, axis=1)


@dataclasses.dataclass(frozen=True)
class LoopStats:
    """One loop's figures in Table I's terms (m).

    Attributes:
        moves: Moves measured.
        mean_error: Mean of |tip - point|.
        spread: +-(max - min) / 2 per axis (3,).
        seconds_per_move: Time per repetition (retract, move, corrections, measurements), s.
        corrections_per_move: Closed-loop correction moves per repetition.
    """

    moves: int
    mean_error: float
    spread: Array
    seconds_per_move: float = 0.0
    corrections_per_move: float = 0.0

    @property
    def mean_spread(self) -> float:
        """The +- spread averaged over x, y, z (Table I: "in each dimension")."""
        return float(self.spread.mean())

    @classmethod
    def of(cls, result: RepeatabilityResult | None) -> LoopStats | None:
        """The figures of ``result``; None before its first move was measured."""
        if result is None or len(result.tips) == 0:
            return None
        k = len(result.tips)
        return cls(k, float(result.errors.mean()), result.spread, result.seconds / k,
                   result.corrections / k)


@dataclasses.dataclass(frozen=True)
class Comparison:
    """Open loop, then closed loop: ``requested`` moves each to ``point``, measured so far.

    Attributes:
        point: The point (3,), m.
        requested: Moves asked per loop.
        segments: The arm's segment count (Table I reports one and two).
        sensor: A tip sensor measured the tips (``serve.py --slip``). Without one only the open
            loop runs, measured by the encoders, and there is no closed loop to compare.
        open: The open loop's result so far (None before it started).
        closed: The closed loop's result so far (None before it started).
        message: Why the run ended early ("stopped", a failed move), else "".
        finished: The run is over (done, stopped or failed).
    """

    point: Array
    requested: int
    segments: int
    sensor: bool
    open: RepeatabilityResult | None = None
    closed: RepeatabilityResult | None = None
    message: str = ""
    finished: bool = False

    @property
    def total(self) -> int:
        """Moves in the whole run."""
        return self.requested * (2 if self.sensor else 1)

    @property
    def done(self) -> int:
        """Moves measured so far."""
        return sum(len(r.tips) for r in (self.open, self.closed) if r is not None)

    def stats(self, loop: Loop) -> LoopStats | None:
        return LoopStats.of(self.open if loop == "open" else self.closed)

    @property
    def state(self) -> str:
        """running | done | stopped (ended early, ``message`` says why)."""
        if not self.finished:
            return "running"
        return "stopped" if self.message else "done"


def _cell(testid: str, value_m: float | None, decimals: int = 1, prefix: str = "") -> str:
    style = "padding:1px 4px;text-align:right"
    if value_m is None or not math.isfinite(value_m):
        return f'<td style="{style}" data-testid="{testid}">—</td>'
    return (f'<td style="{style}" data-testid="{testid}" data-mm="{value_m * 1e3:.4f}">'
            f"{prefix}{fmt_mm(value_m, decimals)}</td>")


_TD = "padding:1px 4px;text-align:center"


def _loop_row(c: Comparison, loop: Loop) -> str:
    s = c.stats(loop)
    name = f'<td style="padding:1px 4px"><span style="color:{COLOURS[loop]}">●</span> {LABELS[loop]}</td>'
    if loop == "closed" and not c.sensor:
        return (f'<tr data-testid="rep-row-closed" style="opacity:.55">{name}<td colspan="4" '
                'style="padding:1px 4px">needs the tip sensor (serve.py --slip F)</td></tr>')
    result = c.open if loop == "open" else c.closed
    moves = f"{0 if result is None else len(result.tips)}/{c.requested}"
    return (f'<tr data-testid="rep-row-{loop}">{name}<td style="{_TD}">{c.segments}</td>'
            f'<td style="{_TD}" data-testid="rep-{loop}-moves">{moves}</td>'
            + _cell(f"rep-{loop}-mean", None if s is None else s.mean_error)
            + _cell(f"rep-{loop}-spread", None if s is None else s.mean_spread, prefix="±")
            + "</tr>")


def _detail_lines(c: Comparison) -> str:
    """Each loop's +- spread per axis (the table shows their mean) and its time per move."""
    axes, cost = [], []
    loops: tuple[Loop, ...] = ("open", "closed")
    for loop in loops:
        s = c.stats(loop)
        if s is None:
            continue
        axes.append(f'{loop} <span data-testid="rep-{loop}-axes">'
                    f"{' / '.join(fmt_mm(v, 1) for v in s.spread)}</span>")
        fixes = (f" ({s.corrections_per_move:.1f} corrections per move)"
                 if loop == "closed" else "")
        cost.append(f'{loop} <span data-testid="rep-{loop}-seconds">'
                    f"{s.seconds_per_move:.1f}</span> s{fixes}")
    if not axes:
        return ""
    return (f"<div>± per axis x / y / z (mm): {' · '.join(axes)}</div>"
            f"<div>Time per move (retract, move, measure): {' · '.join(cost)}</div>")


def _table_i_rows(segments: int) -> str:
    rows = []
    for n, pm in sorted(TABLE_I_MM.items()):
        fade = "" if n == segments else "opacity:.55;"
        rows.append(
            f'<tr data-testid="rep-row-table-i-{n}" style="{fade}font-style:italic">'
            f'<td style="padding:1px 4px">Table I, hardware, open loop</td>'
            f'<td style="{_TD}">{n}</td><td style="{_TD}">5×3</td><td style="{_TD}">—</td>'
            f'<td style="padding:1px 4px;text-align:right" data-testid="rep-table-i-{n}" '
            f'data-mm="{pm:.4f}">±{pm:.0f}</td></tr>')
    return "".join(rows)


def verdict(c: Comparison) -> str:
    """One line: how the closed loop did against the open loop (empty until both measured).

    The spread and mean error need every requested move: until each loop has them the line
    says "k of n" moves measured and no verdict (a spread of one move is 0, which would make
    the closed loop "beat" the open loop infinitely after its first move); a run that ended
    short says that it gives no verdict.
    """
    o, k = c.stats("open"), c.stats("closed")
    if o is None or k is None:
        return ""
    n = c.requested
    short = [(loop, len(r.tips)) for loop, r in (("open", c.open), ("closed", c.closed))
             if r is not None and len(r.tips) < n]
    if short:
        counts = ", ".join(f"{got} of {n} {loop}-loop moves" for loop, got in short)
        if c.finished:
            return f"No verdict: the run ended with {counts} measured."
        return f"Verdict after all {n} moves of each loop: {counts} measured so far."
    ratio = o.mean_spread / k.mean_spread if k.mean_spread > 0 else math.inf
    better = k.mean_spread < o.mean_spread and k.mean_error < o.mean_error
    times = "∞" if math.isinf(ratio) else f"{ratio:.1f}"
    return (f"{'✔ Closed loop beats open loop' if better else '✘ Closed loop does not beat open loop'}"
            f": ± spread {fmt_mm(k.mean_spread)} vs {fmt_mm(o.mean_spread)} mm ({times}× smaller),"
            f" mean error {fmt_mm(k.mean_error)} vs {fmt_mm(o.mean_error)} mm.")


def comparison_html(c: Comparison) -> str:
    """The comparison table with Table I's rows, a verdict line and what measured the tips."""
    head = "".join(f'<th style="padding:1px 4px;font-weight:600">{h}</th>' for h in (
        "", "seg&shy;ments", "moves", "mean error (mm)", "± spread (mm)"))
    measured = ("tips measured by the tip sensor (the emulator: the true tip plus noise; the "
                "encoders cannot see slip)" if c.sensor else
                "tips measured by the encoders (no tip sensor: they cannot see slip)")
    line = verdict(c)
    stop = f' · <b data-testid="rep-message">{html.escape(c.message)}</b>' if c.message else ""
    return (f'<div data-testid="rep-compare" data-state="{c.state}" style="font-size:0.8em">'
            f"<b>{c.done}/{c.total} moves</b> to ({', '.join(fmt_mm(v, 1) for v in c.point)})"
            f" mm{stop}"
            f"<table style='border-collapse:collapse;width:100%'><tr>{head}</tr>"
            f"{_loop_row(c, 'open')}{_loop_row(c, 'closed')}{_table_i_rows(c.segments)}</table>"
            + (f'<div data-testid="rep-verdict" style="margin-top:3px"><b>{line}</b></div>'
               if line else "") + _detail_lines(c)
            + f"<span style='opacity:.65'>Error: |tip − point|. ± spread: (max − min)/2 per axis"
            f" over the moves, mean of x, y, z (Table I's ±, \"in each dimension\"); {measured}."
            " Table I: 5 moves from retracted to each of 3 points.</span></div>")


def _ticks(top: float) -> list[float]:
    """Round tick values from 0 to at least ``top`` (1, 2, 5 x 10^k steps, at most 5 ticks)."""
    top = max(top, 1e-6)
    for step in (m * 10.0 ** e for e in range(-3, 5) for m in (1.0, 2.0, 5.0)):
        if top / step <= 5:
            return [i * step for i in range(int(math.ceil(top / step - 1e-9)) + 1)]
    return [0.0, top]


def error_plot_svg(c: Comparison, width: int = 300, height: int = 150) -> str:
    """Per-move scatter of the tip error (mm): open loop and closed loop side by side."""
    results = {"open": c.open, "closed": c.closed}
    errs = {k: (np.zeros(0) if r is None else r.errors * 1e3) for k, r in results.items()}
    top = max([float(e.max()) for e in errs.values() if len(e)] + [1.0])
    ticks = _ticks(top)
    y_max = ticks[-1]
    left, right, up, down = 34, 8, 16, 26
    w, h = width - left - right, height - up - down
    n = max(c.requested, 1)

    def x(i: int) -> float:
        return left + w * (i + 0.5) / n

    def y(v: float) -> float:
        return up + h * (1.0 - v / y_max)
    parts = [f'<svg data-testid="rep-plot" xmlns="http://www.w3.org/2000/svg" width="{width}" '
             f'height="{height}" style="font:10px sans-serif;max-width:100%">']
    for t in ticks:
        parts.append(f'<line x1="{left}" x2="{left + w}" y1="{y(t):.1f}" y2="{y(t):.1f}" '
                     f'stroke="#888" stroke-opacity=".25"/><text x="{left - 3}" y="{y(t) + 3:.1f}"'
                     f' text-anchor="end" fill="currentColor">{t:g}</text>')
    for i in range(n):
        if n <= 12 or i % math.ceil(n / 12) == 0:
            parts.append(f'<text x="{x(i):.1f}" y="{up + h + 11}" text-anchor="middle" '
                         f'fill="currentColor">{i + 1}</text>')
    parts.append(f'<text x="{left + w / 2:.1f}" y="{height - 2}" text-anchor="middle" '
                 'fill="currentColor">move</text>')
    parts.append(f'<text x="{left}" y="10" fill="currentColor">tip error (mm)</text>')
    shift = {"open": -3.0, "closed": 3.0}
    for loop, e in errs.items():
        for i, v in enumerate(e):
            parts.append(f'<circle class="rep-dot-{loop}" cx="{x(i) + shift[loop]:.1f}" '
                         f'cy="{y(float(v)):.1f}" r="3.5" fill="{COLOURS[loop]}" '
                         f'data-mm="{v:.3f}"><title>{loop} loop, move {i + 1}: '
                         f"{v:.1f} mm</title></circle>")
    for j, loop in enumerate(("open", "closed")):
        lx = left + w - 140 + 72 * j
        parts.append(f'<circle cx="{lx}" cy="7" r="3.5" fill="{COLOURS[loop]}"/>'
                     f'<text x="{lx + 6}" y="10" fill="currentColor">{loop} loop</text>')
    parts.append("</svg>")
    return "".join(parts)


def sensor_note(sensor: bool) -> str:
    """What the run will compare: with the slip emulator's tip sensor, or why there is nothing."""
    if sensor:
        return ('<div data-testid="rep-note" data-state="slip" style="font-size:0.8em">'
                "Slip emulator on: the racks slip on their pinions (the encoders cannot see it) "
                "and a tip sensor measures the tip. <b>Run</b> moves to the point from retracted "
                "N times open loop, then N times closed loop on the tip.</div>")
    return ('<div data-testid="rep-note" data-state="no-slip" style="font-size:0.8em;'
            'color:#e8590c">⚠ Slip emulator off (no <code>--slip</code>): no tip sensor, and the '
            "emulated racks do not slip, so the open loop already repeats (encoder quantisation "
            "only) and a closed loop has nothing to beat. Start <code>serve.py --robot "
            "extensible --slip 0.2</code> to compare; <b>Run</b> here measures the open loop "
            "by the encoders.</div>")
