"""What the Repeatability panel shows: a run's tips in Table I's terms (mm, +- spread).

Kept apart from the panel (widgets, worker thread) so the numbers and their rendering are plain
functions of the measured tips.
"""

from __future__ import annotations

import dataclasses
import html

import numpy as np
import numpy.typing as npt

from core.units import fmt_mm

Array = npt.NDArray[np.float64]
_AXES = ("x", "y", "z")


@dataclasses.dataclass(frozen=True)
class RepeatabilityResult:
    """Tips reached (k, 3) for a point; ``message`` says why fewer than asked, if so."""

    point: Array
    tips: Array
    requested: int
    message: str = ""
    source: str = "encoders"  # what measured the tips: "encoders" | "tip sensor"
    closed_loop: bool = False

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


def result_html(r: RepeatabilityResult) -> str:
    """Per-axis table in mm, cells tagged ``data-testid="rep-<stat>-<axis>"``."""
    cell = "padding:1px 6px;text-align:right"
    rows = [("mean", "mean", r.mean - 0.0), ("spread", "± spread", r.spread),
            ("std", "std", r.std), ("offset", "mean − point", r.offset)]
    head = "".join(f'<th style="{cell}">{a} (mm)</th>' for a in _AXES)
    body = "".join(
        f'<tr><td style="{cell};text-align:left">{label}</td>'
        + "".join(f'<td style="{cell}" data-testid="rep-{key}-{a}">{fmt_mm(v, 2)}</td>'
                  for a, v in zip(_AXES, values)) + "</tr>"
        for key, label, values in rows)
    note = f" · {html.escape(r.message)}" if r.message else ""
    return (f'<div data-testid="rep-result" style="font-size:0.85em">'
            f"<b>{len(r.tips)}/{r.requested} runs</b> to "
            f"({', '.join(fmt_mm(v, 1) for v in r.point)}) mm{note}"
            f"<table style='border-collapse:collapse'><tr><th></th>{head}</tr>{body}"
            f"</table><span style='opacity:.6'>tip from the {r.source}"
            f"{' (closed loop on it)' if r.closed_loop else ''}; spread = ±(max − min)/2 "
            "as in Table I (hardware, open loop: ±19 mm one segment, ±29 mm two)</span></div>")
