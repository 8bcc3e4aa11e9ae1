"""How fast a recording too big to read is refused, side by side with a baseline in the same run.

tests/console/test_recording_budget*.py check that huge recordings are refused with the line
that is wrong and without the reader growing; the time it takes is measured here (the suite runs
those tests beside one another on two busy cores). Goal: a one-line gigabyte is refused within
1 s (console.recording.recorder's ReadBudget: one line at most 1024 kB).

Rows (``--runs`` each; median and max, ms):
  one-line 1 GB refused      load_recording of a gzip file whose second line is 1 GB of zero
                             bytes (written as repeated gzip members: ~1 MB on disk)
     baseline: inflate 1 MB  gzip.open(...).read(1 MB) of the same file: the least the refusal
                             has to read before it knows the line is too long

Run: .venv/bin/python benchmarks/bench_recording_budget.py [--runs 5]
"""

from __future__ import annotations

import argparse
import gzip
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from console.core.model import model_for  # noqa: E402
from console.recording.recorder import FORMAT, load_recording  # noqa: E402
from core.robots import load  # noqa: E402

GB = 1 << 30


def write_one_line_gigabyte(path: Path, robot_name: str = "soft-arm") -> object:
    """A recording of ``robot_name`` whose second line is 1 GB long; returns the arm's model.

    The header is one gzip member, then one member of a 1 MB block of zero bytes is written
    again and again (a gzip stream is its members' concatenation), so the gigabyte is
    compressed once."""
    model = model_for(load(robot_name))
    head = (json.dumps({"kind": "header", "format": FORMAT, "robot": robot_name,
                        "robot_kind": model.kind, "shape": list(model.shape)}) + "\n").encode()
    member = gzip.compress(b"\0" * (1 << 20), compresslevel=1)
    with open(path, "wb") as f:
        f.write(gzip.compress(head + b'{"t": 0, "kind": "state", "q": "', compresslevel=1))
        for _ in range(GB >> 20):
            f.write(member)
    return model


def refuse_ms(path: Path, model: object) -> float:
    t0 = time.perf_counter()
    try:
        load_recording(path, model)
    except ValueError as exc:
        assert "longer than" in str(exc), exc
    else:
        raise AssertionError("the one-line gigabyte was read")
    return (time.perf_counter() - t0) * 1e3


def inflate_ms(path: Path) -> float:
    t0 = time.perf_counter()
    with gzip.open(path, "rb") as f:
        f.read(1 << 20)
    return (time.perf_counter() - t0) * 1e3


def row(name: str, values: list[float], goal: str = "") -> None:
    print(f"  {name:<26} median {statistics.median(values):8.2f} ms   max {max(values):8.2f} ms"
          f"   {goal}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "oneline.jsonl.gz"
        model = write_one_line_gigabyte(path)
        print(f"one-line 1 GB recording, {path.stat().st_size / 1e6:.1f} MB on disk, "
              f"{args.runs} runs each")
        row("one-line 1 GB refused", [refuse_ms(path, model) for _ in range(args.runs)],
            "goal <= 1000 ms")
        row("   baseline: inflate 1 MB", [inflate_ms(path) for _ in range(args.runs)])
    return 0


if __name__ == "__main__":
    sys.exit(main())
