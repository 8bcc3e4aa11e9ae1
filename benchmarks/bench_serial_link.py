"""Serial link benchmark: 16 motors at 100 Hz over the emulator's pseudo-terminal.

Goal (issue 4): nothing lost, round trip p99 <= 2 ms over 5 minutes (``--seconds 300``).
Two hosts run against the same emulator in one run, one after the other:

* **ours**: streamed DEMANDs on an absolute 100 Hz schedule, chunked reads (``read(in_waiting
  or 1)``), decode on arrival (``hw_bridge.link.Link``);
* **baseline**: naive request/response per tick, ``write`` then ``read_until(b"\\x00")``
  for the reply (pyserial reads byte by byte) and decode.

Round trip = DEMAND written -> STATE echoing its seq decoded. Usage:
``python benchmarks/bench_serial_link.py [--seconds 20] [--motors 16] [--baud 1000000]``
(``--baud 0`` disables the emulator's wire-time model, like the Due's native USB port).

Scheduling (``--rt P``, default 50): each host runs under ``SCHED_FIFO`` P, as the console's
control loop does, and the emulator under P + 10, standing in for a microcontroller that nothing
on the machine can delay; ``--rt 0`` runs everything at normal priority (then other load on
this 2-core machine shows in the tail). What each side got is printed.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import serial

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from hw_bridge import protocol as p  # noqa: E402
from hw_bridge.link import Link  # noqa: E402
from hw_bridge.realtime import set_fifo  # noqa: E402
from hw_bridge.transport import open_serial  # noqa: E402


def ours(port: str, baud: int, motors: int, seconds: float) -> dict:
    t = open_serial(port, baud)
    link = Link(t)
    link.all_rtts = []
    t.reset_input()
    link.send(p.Hello())
    end = time.perf_counter() + 0.5
    while time.perf_counter() < end and not any(isinstance(m, p.Hello) for m in link.poll()):
        pass
    counts = np.zeros(motors, dtype=np.int64)
    period = 0.01
    nxt = time.perf_counter()
    end = nxt + seconds
    overruns = 0
    while True:
        now = time.perf_counter()
        if now >= nxt:
            if now >= end:
                break
            counts += 1
            link.send_demand(counts)
            nxt += period
            if nxt <= now:
                nxt = now + period
                overruns += 1
        link.poll()
    drain = time.perf_counter() + 0.1
    while time.perf_counter() < drain:
        link.poll()
    link.finish()
    t.close()
    return {"sent": link.counters.sent, "lost": link.counters.lost,
            "crc_errors": link.decoder.stats.crc_errors, "overruns": overruns,
            "rtt_ms": link.rtt_percentiles_ms(link.all_rtts)}


def baseline(port: str, baud: int, motors: int, seconds: float) -> dict:
    ser = serial.serial_for_url(port, baudrate=baud or 115200, timeout=0.05)
    ser.reset_input_buffer()
    ser.write(p.encode(p.Hello()))  # resets the device's sequence window
    time.sleep(0.05)
    ser.reset_input_buffer()
    dec = p.StreamDecoder()
    rtts: list[float] = []
    sent = lost = 0
    counts = [0] * motors
    period = 0.01
    nxt = time.perf_counter()
    end = nxt + seconds
    seq = 0
    while time.perf_counter() < end:
        seq += 1
        counts = [c + 1 for c in counts]
        t0 = time.perf_counter()
        ser.write(p.encode(p.Demand.full(seq, counts)))
        sent += 1
        got = False
        while time.perf_counter() - t0 < period:  # reply must come within the tick
            frame = ser.read_until(b"\x00")
            if not frame:
                break
            msgs = dec.feed(frame)
            if any(isinstance(m, p.State) and m.ack_seq == seq for m in msgs):
                rtts.append(time.perf_counter() - t0)
                got = True
                break
        lost += not got
        nxt += period
        time.sleep(max(0.0, nxt - time.perf_counter()))
    ser.close()
    a = np.asarray(rtts) * 1000
    return {"sent": sent, "lost": lost, "crc_errors": dec.stats.crc_errors, "overruns": 0,
            "rtt_ms": {"p50": round(float(np.percentile(a, 50)), 3) if a.size else None,
                       "p99": round(float(np.percentile(a, 99)), 3) if a.size else None}}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--baseline-seconds", type=float, default=None,
                    help="baseline duration (default: same as --seconds)")
    ap.add_argument("--motors", type=int, default=16)
    ap.add_argument("--baud", type=int, default=1_000_000)
    ap.add_argument("--robot", default="extensible")
    ap.add_argument("--rt", type=int, default=50, metavar="P",
                    help="SCHED_FIFO priority of the hosts (emulator: P + 10); 0: normal")
    args = ap.parse_args()
    if not 0 <= args.rt <= 89:
        ap.error("--rt must be in 0..89")
    emu_rt = ["--sched-priority", str(args.rt + 10)] if args.rt else []
    emu = subprocess.Popen([sys.executable, "-m", "hw_bridge.emulator", "--robot", args.robot,
                            "--motors", str(args.motors), "--baud", str(args.baud), *emu_rt],
                           cwd=ROOT, stdout=subprocess.PIPE, text=True)
    host_sched = set_fifo(args.rt) if args.rt else "default (SCHED_OTHER)"
    try:
        assert emu.stdout is not None
        port = emu.stdout.readline().strip()
        a = ours(port, args.baud, args.motors, args.seconds)
        b = baseline(port, args.baud, args.motors, args.baseline_seconds or args.seconds)
    finally:
        emu.terminate()
        emu.wait(timeout=5)
    print(f"{args.motors} motors @ 100 Hz, emulator wire model {args.baud or 'off'} baud, "
          f"{args.seconds:g} s; hosts {host_sched}, emulator "
          f"{'SCHED_FIFO ' + str(args.rt + 10) if args.rt else 'default'}")
    print(f"{'':10s}{'sent':>8s}{'lost':>7s}{'crc':>6s}{'rtt p50 ms':>12s}{'rtt p99 ms':>12s}")
    for name, r in (("ours", a), ("baseline", b)):
        print(f"{name:10s}{r['sent']:8d}{r['lost']:7d}{r['crc_errors']:6d}"
              f"{r['rtt_ms']['p50']!s:>12s}{r['rtt_ms']['p99']!s:>12s}")
    print(json.dumps({"ours": a, "baseline": b}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
