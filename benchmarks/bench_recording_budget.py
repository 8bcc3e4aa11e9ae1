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

and the size of every loop tick (issue 29: ``/control/ticks``, ``/control/extensible_ticks``):
each arm's real loop process (simulated soft arm doing grasp-and-place; extensible arm on its
mock device doing moves) recorded through the console's Recorder for ``--tick-seconds``; the
tick channel alone is written again into an MCAP file with the same settings (zstd chunks) and
its size printed per minute beside the whole recording's. Goal: 10 min <= 100 MB.

Run: .venv/bin/python benchmarks/bench_recording_budget.py [--runs 5] [--tick-seconds 30]
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


def _ticks_only(path: Path, topic: str, out: Path) -> tuple[int, float, int]:
    """Write ``topic`` of recording ``path`` alone into ``out`` (same writer settings); returns
    (ticks, seconds of loop time they span, deadlines the loop missed meanwhile)."""
    from mcap.reader import make_reader
    from core.labdata.mcap_file import McapLog

    n, t0, t1, missed = 0, None, 0.0, 0
    with open(path, "rb") as f, McapLog(out, {"robot": "bench"}, 0) as log:
        for _, _, m in make_reader(f).iter_messages(topics=[topic], log_time_order=True):
            msg = json.loads(m.data)
            log.write(topic, msg, m.log_time, clamp=False)
            n += 1
            t0 = msg["t_s"] if t0 is None else t0
            t1 = msg["t_s"]
            missed += int(msg.get("missed", 0))
    return n, t1 - (t0 or 0.0), missed


def _wait(pred, timeout: float = 120.0) -> None:
    end = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > end:
            raise TimeoutError("the loop process did not get there")
        time.sleep(0.05)


def soft_arm_recording(tmp: Path, seconds: float) -> Path:
    """``seconds`` of the soft arm's loop process recorded while it grasps and places."""
    from console.core.datadir import DataDir
    from console.recording.recorder import Recorder
    from core.control.trials import paper_locations
    from hw_bridge.soft_arm_process import ControlProcess

    robot = load("soft-arm")
    ctl = ControlProcess(robot, seed=1, device="sim", sched_priority=None, cpus=None)
    rec = Recorder(DataDir(tmp), model_for(robot), suffix=".mcap")
    ctl.tick_listeners.append(rec.on_ticks)
    try:
        _wait(lambda: ctl.view is not None and ctl.view.snapshot.control is not None)
        path = rec.start("soft")
        ctl.arm().result(30)
        _wait(lambda: ctl.view.snapshot.control.prepressurised)
        spots = list(paper_locations().values())
        end, i = time.monotonic() + seconds, 0
        while time.monotonic() < end:
            if ctl.view.snapshot.control.phase in ("idle", "released", "stopped"):
                x, y = spots[i % len(spots)]
                ctl.grasp_at(x, y, 0.0165).result(30)
                i += 1
            rec.on_state(_soft_state(robot, ctl))
            time.sleep(1 / 30)  # the render thread's states beside the ticks
        rec.stop()
        return path
    finally:
        ctl.close()


def _soft_state(robot: object, ctl: object) -> object:
    from console.core.state import ArmState
    c = ctl.view.snapshot.control  # type: ignore[attr-defined]
    q = c.kappa_meas if c.kappa_meas is not None else c.kappa_ref
    return ArmState(q=q, seq=int(ctl.view.snapshot.tick), source="loop")  # type: ignore


def extensible_recording(tmp: Path, seconds: float) -> Path:
    """``seconds`` of the extensible arm's loop process recorded while it moves."""
    import numpy as np
    from console.core.datadir import DataDir
    from console.core.state import StateStore
    from console.recording.recorder import Recorder
    from core.kinematics import delta as dk
    from hw_bridge.extensible_process import ExtensibleProcess

    robot = load("extensible")
    store = StateStore(model_for(robot), mirror_commands=True)
    proc = ExtensibleProcess(robot, store, "mock", cpus=None, sched_priority=None)
    rec = Recorder(DataDir(tmp), model_for(robot), suffix=".mcap")
    proc.tick_listeners.append(rec.on_ticks)
    try:
        proc.start()
        proc.connecting.result(30)
        _wait(lambda: proc.snapshot.state == "disarmed")
        path = rec.start("ext")
        proc.bridge_controls.arm()
        _wait(lambda: proc.snapshot.state in ("holding", "following"))
        targets = [np.array([[0.01, 0.0, 0.05], [0.0, -0.01, 0.04]]),
                   np.array([[-0.01, 0.01, 0.03], [0.01, 0.0, 0.05]])]
        end, i = time.monotonic() + seconds, 0
        while time.monotonic() < end:
            proc.wait(proc.move_to(dk.robot_rack_lengths(robot, targets[i % 2])), timeout=60)
            i += 1
        rec.stop()
        return path
    finally:
        proc.close()


def tick_sizes(seconds: float) -> None:
    """Print MB per minute of each arm's tick channel and of its whole recording."""
    print(f"every loop tick, {seconds:g} s of each arm's loop process recorded "
          "(goal: 10 min <= 100 MB)")
    for name, make, topic in (("soft arm", soft_arm_recording, "/control/ticks"),
                              ("extensible", extensible_recording,
                               "/control/extensible_ticks")):
        with tempfile.TemporaryDirectory() as tmp:
            path = make(Path(tmp), seconds)
            n, span, missed = _ticks_only(path, topic, Path(tmp) / "ticks.mcap")
            ticks_mb = (Path(tmp) / "ticks.mcap").stat().st_size / 1e6
            whole_mb = path.stat().st_size / 1e6
            # Per minute at the full 100 Hz (6000 ticks), whatever rate this machine's load
            # left the loop (a tick the loop skipped is a missed deadline, not a lost row).
            scale = 6000.0 / max(n, 1)
            extra = (whole_mb - ticks_mb) * 60.0 / max(span, 1e-9)
            print(f"  {name:<11} {n} ticks in {span:.1f} s of loop time ({missed} deadlines "
                  f"missed under this load), {ticks_mb * 1e6 / max(n, 1):.0f} B/tick: tick "
                  f"channel {ticks_mb * scale:.2f} MB/min at 100 Hz "
                  f"({ticks_mb * scale * 10:.1f} MB per 10 min); whole recording "
                  f"{ticks_mb * scale + extra:.2f} MB/min "
                  f"({(ticks_mb * scale + extra) * 10:.1f} MB per 10 min)")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--tick-seconds", type=float, default=30.0,
                    help="seconds of each arm's loop recorded for the tick sizes (0: skip)")
    args = ap.parse_args()
    if args.tick_seconds > 0:
        tick_sizes(args.tick_seconds)
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
