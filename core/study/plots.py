"""A design study's PNG plots: each metric over the varied keys, for slides and lab notebooks.

One ``<metric>.png`` per metric that some variant computed. The x axis is the varied key with the
most values (its numbers, as varied); each combination of the other varied keys is one line
(named in the legend), its variants solid dots on a lighter line; a variant that failed is a gap
in its line and a red cross on the x axis. The title names the best variant (largest value, or
smallest where smaller is better) and how many failed.

Drawn with matplotlib's object-oriented API on its Agg canvas (no ``pyplot``: no global figure
state, no display), imported lazily: matplotlib comes with the ``study`` extra
(``pip install .[study]``); without it :func:`write_pngs` raises :class:`PlotsUnavailable`,
which the command line reports in one line while the tables and the HTML report stand.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any, Mapping, Sequence

WIDTH_IN, HEIGHT_IN, DPI = 6.4, 4.0, 100
"""Figure size (inches) and resolution: 640 x 400 pixels."""
LINE_COLOURS = ("#3b7dd8", "#d87b3b", "#3bb36b", "#9b59b6", "#c0392b", "#7f8c8d")
"""Line colours, one per combination of the keys not on the x axis (cycled)."""
FAILED_COLOUR = "#cc0000"
"""The cross marking a failed variant on the x axis."""


class PlotsUnavailable(RuntimeError):
    """matplotlib is not installed (the ``study`` extra)."""


def x_key(rows: Sequence[Mapping[str, Any]], keys: Sequence[str]) -> str:
    """The varied key with the most distinct values (the first such key on a tie)."""
    return max(keys, key=lambda k: len({r.get(k) for r in rows}))


def series(rows: Sequence[Mapping[str, Any]], keys: Sequence[str],
           metric: str) -> tuple[str, dict[str, list[tuple[float, float]]]]:
    """``(x key, {line label: [(x, value), ...] in x order})``; a failed or missing value is NaN.

    The label names the other keys' values (``""`` when only one key is varied)."""
    xk = x_key(rows, keys)
    others = [k for k in keys if k != xk]
    lines: dict[str, list[tuple[float, float]]] = {}
    for r in rows:
        label = ", ".join(f"{k}={r.get(k)}" for k in others)
        v = math.nan if r.get("error") else float(r.get(metric, math.nan))
        lines.setdefault(label, []).append((float(r[xk]), v))
    return xk, {k: sorted(v) for k, v in lines.items()}


def write_pngs(rows: Sequence[Mapping[str, Any]], keys: Sequence[str], metrics: Sequence[str],
               best: Mapping[str, str], out: Path) -> list[Path]:
    """Write ``out/<metric>.png`` for every metric some row has; returns the files written.

    Raises:
        PlotsUnavailable: matplotlib is not installed.
    """
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        raise PlotsUnavailable("PNG plots need matplotlib: pip install '.[study]'") from None
    written = []
    for metric in metrics:
        if not any(metric in r for r in rows) or not keys:
            continue
        xk, lines = series(rows, keys, metric)
        fig = Figure(figsize=(WIDTH_IN, HEIGHT_IN), dpi=DPI)
        FigureCanvasAgg(fig)
        ax = fig.add_subplot()
        colours = itertools.cycle(LINE_COLOURS)
        failures = 0
        for label, pts in lines.items():
            colour = next(colours)
            xs = [x for x, _ in pts]
            ys = [y for _, y in pts]
            ax.plot(xs, ys, color=colour, alpha=0.45, label=label or None)  # the line, lighter
            ax.plot(xs, ys, "o", color=colour, markersize=7)  # each variant, solid
            failed = [x for x, y in pts if not math.isfinite(y)]
            failures += len(failed)
            if failed:  # on the x axis (axes coordinates in y: the scale is the values')
                ax.plot(failed, [0.03] * len(failed), "x", color=FAILED_COLOUR, markersize=10,
                        markeredgewidth=2.5, transform=ax.get_xaxis_transform())
        ax.set_xlabel(xk)
        ax.set_ylabel(metric)
        title = f"{metric}: best {best.get(metric, 'none')}"
        if failures:
            title += f"; {failures} failed (red x)"
        ax.set_title(title, fontsize=8)
        ax.grid(True, color="#dddddd")
        if any(lines):
            ax.legend(fontsize=7)
        fig.tight_layout()
        out.mkdir(parents=True, exist_ok=True)
        path = out / f"{metric}.png"
        fig.savefig(path, format="png")
        written.append(path)
    return written
