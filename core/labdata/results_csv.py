"""Trial and capture results as CSV beside the JSON, one row per trial / grid point, units in the
header (``name [unit]``; counts, flags and words have none), for spreadsheets and pandas.

Duck-typed on ``core.control.trials.TrialResult`` and ``core.control.capture.CaptureMap``, so
this module imports neither.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any, Sequence

TRIAL_COLUMNS = ("trial", "spot", "seed", "x [m]", "y [m]", "r [m]", "success", "failure",
                 "approach [s]", "return [s]", "simulated [s]", "wall [s]", "ticks", "replans",
                 "stalls", "occlusions", "tick work p99 [ms]", "final x [m]", "final y [m]")
CAPTURE_COLUMNS = ("x [m]", "y [m]", "outcome", "success rate", "object r [m]", "spacing [m]",
                   "repeats", "in model disc")
OUTCOMES = {1: "success", 0: "failure", -1: "infeasible"}


def _cell(value: Any) -> Any:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "" if not math.isfinite(value) else repr(value)
    return value


def _write(path: str | Path, columns: Sequence[str], rows: list[Sequence[Any]]) -> Path:
    path = Path(path)
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(columns)
        for row in rows:
            w.writerow([_cell(v) for v in row])
    return path


def trial_rows(results: Sequence[Any]) -> list[tuple[Any, ...]]:
    """One row per trial, in :data:`TRIAL_COLUMNS` order."""
    rows = []
    for i, r in enumerate(results, 1):
        x, y, rad = (float(v) for v in r.object)
        fx, fy = (None, None) if r.final_object is None else (float(v) for v in r.final_object)
        rows.append((i, r.label, r.seed, x, y, rad, bool(r.success), r.failure or "",
                     float(r.approach_s), float(r.return_s), float(r.sim_s), float(r.wall_s),
                     r.ticks, r.replans, r.stalls, r.occlusions, float(r.work_ms_p99), fx, fy))
    return rows


def write_trials_csv(path: str | Path, results: Sequence[Any]) -> Path:
    """Write trials as CSV (see :data:`TRIAL_COLUMNS`)."""
    return _write(path, TRIAL_COLUMNS, trial_rows(results))


def capture_rows(cmap: Any) -> list[tuple[Any, ...]]:
    """One row per grid point (x fastest, then y), in :data:`CAPTURE_COLUMNS` order."""
    import numpy as np

    rows = []
    for j, y in enumerate(cmap.ys):
        inside = cmap.model.contains(np.column_stack([cmap.xs, np.full(len(cmap.xs), y)]))
        for i, x in enumerate(cmap.xs):
            rows.append((float(x), float(y), OUTCOMES[int(cmap.outcome[j, i])],
                         float(cmap.rate[j, i]), float(cmap.radius), float(cmap.spacing),
                         int(cmap.repeats), bool(inside[i])))
    return rows


def write_capture_csv(path: str | Path, cmap: Any) -> Path:
    """Write a capture characterisation as CSV (see :data:`CAPTURE_COLUMNS`)."""
    return _write(path, CAPTURE_COLUMNS, capture_rows(cmap))
