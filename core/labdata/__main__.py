"""``python -m core.labdata convert OLD.jsonl.gz NEW.mcap``, ``info FILE.mcap`` and
``export FILE.mcap --out DIR``.

``convert`` turns a recording in the older gzip'd JSON-lines format into an MCAP recording with
the same records (the replay shows the same run) plus the lab channels (3D scene, tip pose,
log); the robot is the one named in the old header (``--robot`` to override). ``info`` prints
the channels, schema names and message counts of an MCAP file. ``export`` writes one table per
channel (CSV and Parquet, units in the column names: :mod:`core.labdata.export`).
"""

from __future__ import annotations

import argparse
import calendar
import gzip
import json
import sys
import time
import zlib
from pathlib import Path
from typing import Any, Sequence

from core.labdata.channels import ArmGeometry
from core.labdata.mcap_file import McapLog
from core.labdata.progress import progress_bar
from core.robots import load

OLD_FORMAT = "softarm-console-recording/1"


def _start_ns(started: Any) -> int:
    try:
        return calendar.timegm(time.strptime(str(started)[:19], "%Y-%m-%dT%H:%M:%S")) \
            * 1_000_000_000 - _utc_offset_ns(str(started))
    except ValueError:
        return 0


def _utc_offset_ns(started: str) -> int:
    tail = started[19:]  # "+0100" / "-0530" / ""
    if len(tail) == 5 and tail[0] in "+-" and tail[1:].isdigit():
        sign = 1 if tail[0] == "+" else -1
        return sign * (int(tail[1:3]) * 3600 + int(tail[3:5]) * 60) * 1_000_000_000
    return 0


def convert(old: Path, new: Path, robot_name: str | None = None,
            show_progress: bool | None = None) -> int:
    """Convert ``old`` (``.jsonl.gz``) to ``new`` (``.mcap``); returns the records written.

    Raises:
        ValueError: ``old`` is not a console recording or cannot be read; ``new`` exists.
    """
    if new.exists():
        raise ValueError(f"{new} exists; choose a new file name")
    size = old.stat().st_size
    records = 0
    log: McapLog | None = None
    bar = progress_bar(size, f"convert {old.name}", unit="B", unit_scale=True,
                       force=show_progress)
    try:
        with open(old, "rb") as raw, gzip.open(raw, "rt", encoding="utf-8") as f:
            for n, line in enumerate(f):
                rec = json.loads(line)
                if not isinstance(rec, dict):
                    raise ValueError(f"{old.name}: line {n + 1} is not an object")
                if n == 0:
                    if rec.get("kind") != "header" or rec.get("format") != OLD_FORMAT:
                        raise ValueError(f"{old.name} is not a console recording")
                    robot = load(robot_name or str(rec.get("robot")))
                    header = {k: v for k, v in rec.items() if k not in ("kind", "t")}
                    header["converted_from"] = old.name
                    log = McapLog(new, header, _start_ns(rec.get("started")),
                                  ArmGeometry(robot))
                    continue
                assert log is not None
                log.record(rec)
                records += 1
                if records % 500 == 0:
                    bar.update(raw.tell() - bar.n)
            bar.update(size - bar.n)
    except (OSError, EOFError, zlib.error, json.JSONDecodeError, UnicodeDecodeError,
            ValueError, KeyError, TypeError) as exc:
        if log is not None:  # no half-converted file left behind
            log.close()
            new.unlink(missing_ok=True)
        if isinstance(exc, ValueError) and not isinstance(exc, (json.JSONDecodeError,
                                                                UnicodeDecodeError)):
            raise
        raise ValueError(f"{old.name}: cannot read ({exc})") from None
    finally:
        bar.close()
        if log is not None:
            log.close()
    if log is None:
        raise ValueError(f"{old.name} is empty")
    return records


def info(path: Path) -> dict[str, Any]:
    """Channels (topic -> schema name, message count) and the time span of an MCAP file."""
    from mcap.reader import make_reader
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    if summary is None or summary.statistics is None:
        raise ValueError(f"{path.name}: no summary (unfinished file? try `mcap recover`)")
    st = summary.statistics
    channels = {}
    for cid, ch in sorted(summary.channels.items()):
        schema = summary.schemas.get(ch.schema_id)
        channels[ch.topic] = {"schema": schema.name if schema else "",
                              "messages": st.channel_message_counts.get(cid, 0)}
    return {"messages": st.message_count, "start_ns": st.message_start_time,
            "end_ns": st.message_end_time, "channels": channels}


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m core.labdata", description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("convert", help="convert an old .jsonl.gz recording to .mcap")
    c.add_argument("old", type=Path)
    c.add_argument("new", type=Path)
    c.add_argument("--robot", help="robot name or TOML (default: the one in the old header)")
    i = sub.add_parser("info", help="channels, schemas and message counts of an .mcap file")
    i.add_argument("file", type=Path)
    e = sub.add_parser("export", help="one table per channel (CSV and Parquet) in a folder")
    e.add_argument("file", type=Path)
    e.add_argument("--out", type=Path, required=True, help="folder for the tables (created)")
    a = ap.parse_args(argv)
    try:
        if a.cmd == "convert":
            if not a.new.name.endswith(".mcap"):
                ap.error(f"{a.new}: the new file must end with .mcap")
            n = convert(a.old, a.new, a.robot)
            print(f"{a.old} -> {a.new}: {n} records")
        elif a.cmd == "export":
            from core.labdata.export import export
            files = export(a.file, a.out)
            print(f"{a.file} -> {a.out}: {len(files) // 2} tables (CSV and Parquet)")
        else:
            print(json.dumps(info(a.file), indent=1))
    except (ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
