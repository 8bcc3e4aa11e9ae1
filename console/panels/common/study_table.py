"""A design study's table and plot as people read them: mm and degrees where a column's unit says so.

core.study names each column with its SI unit (``reachable_area_m2``, ``workspace_volume_m3``;
see docs/design-studies.md); :func:`column_unit` reads that suffix and gives the unit shown
(mm, mm², mm³, degrees, mm/s, deg/s, s) and the factor from SI. Columns without a unit suffix
(counts, rates, the varied robot-file keys) are shown as the file holds them. Pure functions
(no viser) used by :class:`console.panels.common.design_study.DesignStudyPanel`.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import re
from typing import Any

import numpy as np
import numpy.typing as npt

from console.core.design_study import StudyResults

MAX_TABLE_ROWS = 200   # rows shown in the panel; the rest are in results.csv
MAX_LINES = 8          # plot lines (one per combination of the other varied keys)
THIN = "\u202f"        # thousands separator: a narrow no-break space

# SI suffix -> (unit on screen, factor from SI, decimals); longest suffixes first.
UNITS: tuple[tuple[str, str, float, int], ...] = (
    ("_rad_s", "deg/s", 180.0 / math.pi, 1),
    ("_m_s", "mm/s", 1e3, 1),
    ("_m3", "mm³", 1e9, 0),
    ("_m2", "mm²", 1e6, 0),
    ("_rad", "deg", 180.0 / math.pi, 1),
    ("_mm", "mm", 1.0, 1),
    ("_m", "mm", 1e3, 1),
    ("_s", "s", 1.0, 2),
)


@dataclasses.dataclass(frozen=True)
class ColumnUnit:
    """How one column is shown.

    Attributes:
        name: The column's name without its unit suffix.
        unit: The unit on screen ("" for none).
        scale: Factor from the file's value to the screen's.
        decimals: Decimals shown (None: four significant digits).
    """

    name: str
    unit: str
    scale: float
    decimals: int | None

    @property
    def header(self) -> str:
        """The column header, unit in brackets: ``reachable_area (mm²)``."""
        return f"{self.name} ({self.unit})" if self.unit else self.name


def column_unit(column: str) -> ColumnUnit:
    """The screen unit of ``column`` from its SI suffix (none: shown as in the file)."""
    for suffix, unit, scale, decimals in UNITS:
        if column.endswith(suffix) and len(column) > len(suffix) and "." not in column:
            return ColumnUnit(column[: -len(suffix)], unit, scale, decimals)
    return ColumnUnit(column, "", 1.0, None)


def fmt_value(column: str, value: Any) -> str:
    """One cell on screen (numbers in the column's screen unit, without the unit)."""
    if value is None:
        return ""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return str(value)
    u = column_unit(column)
    v = float(value) * u.scale
    if not math.isfinite(v):
        return "–" if math.isnan(v) else str(v)
    if u.decimals is None:
        return str(value) if isinstance(value, int) else f"{v:.4g}"
    text = f"{v:,.{u.decimals}f}".replace(",", THIN)
    return text.lstrip("-") if not text.lstrip("-").strip("0.,\u202f") else text


def _md(text: str, limit: int = 120) -> str:
    """Text for a markdown table cell: pipes and newlines escaped, shortened."""
    text = re.sub(r"\s*[\r\n\t]+\s*", " ", str(text))
    if len(text) > limit:
        text = text[: limit - 1] + "…"
    return text.replace("\\", "\\\\").replace("|", "\\|").replace("*", "\\*").replace("_", "\\_")


def _code(name: str) -> str:
    """A variant's name as inline code in a table cell."""
    return "`" + str(name).replace("`", "'").replace("|", "\\|") + "`"


def table_markdown(results: StudyResults, max_rows: int = MAX_TABLE_ROWS) -> str:
    """The study as a markdown table: # (the variant's number in the study), the varied keys,
    every metric (screen units; the best value of each bold), the reason of a failed variant;
    then the variants by number and name (their names are long: a narrow panel's table holds
    the numbers) and the best variant per metric, by name."""
    errors = any(r.get("error") for r in results.rows)
    cols = [*results.keys, *results.metrics]
    head = ["#", *(column_unit(c).header for c in cols)] + (["error"] if errors else [])
    lines = ["| " + " | ".join(_md(h) for h in head) + " |",
             "|" + "---|" * len(head)]
    for i, row in enumerate(results.rows[:max_rows], 1):
        cells = [str(i)]  # the number names the variant: the Variant list and Best lines
        for c in cols:
            text = _md(fmt_value(c, row.get(c)))
            cells.append(f"**{text}**" if results.best.get(c) == row["variant"] else text)
        if errors:
            cells.append(_md(row.get("error") or ""))
        lines.append("| " + " | ".join(cells) + " |")
    more = len(results.rows) - max_rows
    tail = [f"<small>… {more} more rows in {results.label}/{results.source}</small>"] if (
        more > 0) else []
    names = "<br>".join(f"{i}: {_code(name)}" for i, name in
                        enumerate(results.variants[:max_rows], 1))
    return ("\n".join(lines + tail) + "\n\n" + best_markdown(results)
            + f"\n\n<small>{names}</small>")


def best_markdown(results: StudyResults) -> str:
    """The best variant per metric (core.study's rule), one line each, by name and value."""
    if not results.best:
        return "**Best:** none (no variant has a finished metric)"
    rows = {r["variant"]: r for r in results.rows}
    lines = []
    for metric, name in results.best.items():
        u = column_unit(metric)
        value = fmt_value(metric, rows[name].get(metric))
        number = results.variants.index(name) + 1
        lines.append(f"- **Best {_md(u.header)}:** #{number} {_code(name)} ({value}"
                     f"{' ' + u.unit if u.unit else ''})")
    return "\n".join(lines)


@dataclasses.dataclass(frozen=True)
class PlotData:
    """A metric over one varied key: x ascending, one line per combination of the other keys.

    Attributes:
        x: The key's distinct values (as in the robot file), ascending; those where no line
            has a number (every variant there failed) left out.
        lines: One array per line, the metric in screen units at each x (NaN: no such variant
            or it failed).
        labels: Each line's legend (the other keys' values; the metric's header for one line).
        x_label: The key.
        y_label: The metric's header.
        omitted: Lines left out (more than :data:`MAX_LINES`).
    """

    x: npt.NDArray[np.float64]
    lines: tuple[npt.NDArray[np.float64], ...]
    labels: tuple[str, ...]
    x_label: str
    y_label: str
    omitted: int = 0


def plot_data(results: StudyResults, metric: str, over: str) -> PlotData:
    """``metric`` (screen units) over the varied key ``over`` (see :class:`PlotData`).

    Raises:
        KeyError: ``metric`` is not one of the study's metrics or ``over`` not a varied key.
    """
    if metric not in results.metrics:
        raise KeyError(f"{metric!r} is not a metric of {results.label}")
    if over not in results.keys:
        raise KeyError(f"{over!r} is not a varied key of {results.label}")
    u = column_unit(metric)
    key = results.column(over)
    y = results.column(metric) * u.scale
    failed = np.array([bool(r.get("error")) for r in results.rows])
    y[failed] = np.nan
    xs = np.unique(key[np.isfinite(key)])
    others = [k for k in results.keys if k != over]
    groups: dict[tuple[Any, ...], npt.NDArray[np.float64]] = {}
    for row, kx, ky in zip(results.rows, key, y):
        combo = tuple(row.get(k) for k in others)
        line = groups.setdefault(combo, np.full(len(xs), np.nan))
        if math.isfinite(kx):
            line[int(np.searchsorted(xs, kx))] = ky
    combos = list(groups)[:MAX_LINES]
    drawn = np.zeros(len(xs), dtype=bool)  # x values where some line has a number
    for c in combos:
        drawn |= np.isfinite(groups[c])
    xs = xs[drawn]
    groups = {c: line[drawn] for c, line in groups.items()}
    labels = tuple(", ".join(f"{k}={v}" for k, v in zip(others, c)) or u.header for c in combos)
    return PlotData(xs, tuple(groups[c] for c in combos), labels, over, u.header,
                    max(0, len(groups) - MAX_LINES))


def default_metric(results: StudyResults) -> str | None:
    """The metric plotted first: the first one with a best variant, else the first metric."""
    return next(itertools.chain((m for m in results.metrics if m in results.best),
                                iter(results.metrics)), None)
