"""Recordings as plain tables, so a lab can read them in pandas, MATLAB or a spreadsheet.

:func:`export` reads an MCAP recording (every channel) and writes one table per channel into a
folder, as CSV and as Parquet (pyarrow), named after the topic (``/control/ticks`` ->
``control_ticks.csv`` / ``.parquet``). Column names carry their units: the tick channels'
(:func:`core.labdata.ticks.tick_columns`: ``t_s``, ``seg1_kappa_measured_1_per_m``,
``cmd1_counts``, ``period_ms`` ...) and, on the other channels, nested fields joined with ``_``
and a unit appended to a known quantity (``x`` -> ``x_m``, ``kappa`` -> ``kappa_1_per_m``);
``timestamp`` becomes ``timestamp_ns`` and every table starts with ``log_time_ns``. Arrays of
numbers spread over one column per element (``_1``, ``_2`` ...); arrays of objects (a scene's
entities, a table's objects) stay one JSON text column (``..._json``). A value a message does
not have is an empty cell.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

from core.labdata.mcap_file import iter_messages
from core.labdata.ticks import ARM_OF_TOPIC, tick_columns

#: Units appended to these leaf fields (SI; angles in rad).
UNITS = {"x": "m", "y": "m", "z": "m", "r": "m", "radius": "m", "clearance": "m",
         "center": "m", "palm": "m_m_rad", "point": "m", "kappa": "1_per_m", "dx": "m",
         "dy": "m", "dL": "m", "t": "s"}
_HAS_UNIT = ("_m", "_s", "_ms", "_mps", "_counts", "_1_per_m", "_ns", "_rad")


def _named(name: str, leaf: str) -> str:
    unit = UNITS.get(leaf)
    if unit is None or name.endswith(_HAS_UNIT):
        return name
    return f"{name}_{unit}"


def _scalar(v: Any) -> bool:
    return v is None or isinstance(v, (bool, int, float, str))


def flatten(msg: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """One message as a flat row (see the module docstring)."""
    out: dict[str, Any] = {}
    for key, value in msg.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict) and set(value) == {"sec", "nsec"}:
            out[f"{name}_ns"] = int(value["sec"]) * 1_000_000_000 + int(value["nsec"])
        elif isinstance(value, dict):
            out.update(flatten(value, name + "_"))
        elif isinstance(value, list) and all(_scalar(v) and not isinstance(v, str)
                                             for v in value):
            base = _named(name, key)
            for i, v in enumerate(value):
                out[f"{base}_{i + 1}"] = v
        elif isinstance(value, list):
            out[f"{name}_json"] = json.dumps(value, separators=(",", ":"))
        else:
            out[_named(name, key)] = value
    return out


def table_of(topic: str, messages: list[tuple[int, dict[str, Any]]]) -> dict[str, list[Any]]:
    """The columns of one channel's ``(log ns, message)`` list."""
    arm = ARM_OF_TOPIC.get(topic)
    if arm is not None:
        cols = tick_columns([m for _, m in messages], arm)
        cols["log_time_ns"] = [ns for ns, _ in messages]
        return cols
    rows = [flatten(m) for _, m in messages]
    names: dict[str, None] = {"log_time_ns": None}
    for row in rows:
        names.update(dict.fromkeys(row))
    cols = {name: [row.get(name) for row in rows] for name in names}
    cols["log_time_ns"] = [ns for ns, _ in messages]
    return cols


def file_stem(topic: str) -> str:
    """``/control/ticks`` -> ``control_ticks``."""
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in topic.strip("/")) or "root"


def _write_csv(path: Path, cols: dict[str, list[Any]]) -> None:
    names = list(cols)
    n = len(cols[names[0]]) if names else 0
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(names)
        for i in range(n):
            w.writerow(["" if cols[c][i] is None else cols[c][i] for c in names])


def _write_parquet(path: Path, cols: dict[str, list[Any]]) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    arrays = {}
    for name, values in cols.items():
        try:
            arrays[name] = pa.array(values)
        except (pa.ArrowInvalid, pa.ArrowTypeError):  # mixed kinds: kept as text
            arrays[name] = pa.array([None if v is None else str(v) for v in values])
    pq.write_table(pa.table(arrays), path)


def export(path: str | Path, out: str | Path) -> list[Path]:
    """Write every channel of recording ``path`` as ``<stem>.csv`` and ``<stem>.parquet`` in
    folder ``out`` (created); returns the files written, in topic order.

    Raises:
        ValueError: ``path`` cannot be read as an MCAP recording.
    """
    path, out = Path(path), Path(out)
    by_topic: dict[str, list[tuple[int, dict[str, Any]]]] = {}
    try:
        with open(path, "rb") as f:
            for m in iter_messages(f):
                by_topic.setdefault(m.topic, []).append((m.log_time, m.message))
    except (OSError, ValueError):
        raise
    except Exception as exc:  # the mcap package's own errors for foreign or broken files
        raise ValueError(f"{path.name}: cannot read ({type(exc).__name__}: {exc})") from None
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for topic in sorted(by_topic):
        cols = table_of(topic, by_topic[topic])
        stem = file_stem(topic)
        _write_csv(out / f"{stem}.csv", cols)
        _write_parquet(out / f"{stem}.parquet", cols)
        written += [out / f"{stem}.csv", out / f"{stem}.parquet"]
    return written
