"""How soon the link's faults are acted on: a dead host trips the device's watchdog, a cut wire
is noticed by the host and trips the watchdog; each beside the configured timeout in one run.

The extensible arm's device emulator on a pty (``python -m hw_bridge.emulator``) with the
shipped link settings (watchdog 50 ms, host link timeout 40 ms, 100 Hz), at normal priority
like the tests (tests/hw_bridge/test_hw_emulator.py checks the behaviour: these are its
figures). Every time is CLOCK_MONOTONIC in both processes (the emulator's JSON events carry it),
so hops across processes are exact.

* **host killed**: a host process arms the device and streams DEMANDs; it is SIGKILLed; from
  the kill to the emulator's ``watchdog_tripped`` event.
* **wire cut**: ``--disconnect-after 1 --disconnect-for 0.5`` while this process streams
  DEMANDs (:class:`hw_bridge.interface.SerialHardware`): from the emulator's ``link_cut`` to
  the host's read or write returning ERROR (link lost), and to ``watchdog_tripped``. A trial
  whose link was lost before the cut (a stall longer than the timeout) is counted, not timed.

Baseline column: what each should take at most on a punctual machine, the configured timeout
plus one 10 ms period (the device checks its watchdog, and the host reads, once a period; the
time runs from the last DEMAND or STATE, which came up to a period before the kill or the cut).
The tests asserted 150, 100 and 150 ms before these figures moved here.

``python benchmarks/link_faults.py [--trials 5]``; prints p50 / max in ms per row.
"""

from __future__ import annotations

import argparse
import json
import os
import queue
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from core.robots import load  # noqa: E402
from hw_bridge.config import BridgeConfig  # noqa: E402
from hw_bridge.interface import ReturnType, SerialHardware  # noqa: E402

EXT = load("extensible")
HOST = textwrap.dedent("""
    import sys, time
    import numpy as np
    from core.robots import load
    from hw_bridge.config import BridgeConfig
    from hw_bridge.interface import SerialHardware
    hw = SerialHardware(BridgeConfig.from_robot(load("extensible")), sys.argv[1])
    assert hw.configure().value == "ok", hw.fault
    assert hw.activate().value == "ok", hw.fault
    n = 0
    while True:
        hw.read(); hw.write(np.full(6, 100000)); n += 1
        if n == 20:
            print("moving", flush=True)
        time.sleep(0.01)
""")


class Emu:
    """A running emulator; its JSON events on a queue."""

    def __init__(self, *args: str) -> None:
        self.proc = subprocess.Popen([sys.executable, "-m", "hw_bridge.emulator", "--robot",
                                      "extensible", *args], cwd=ROOT, stdout=subprocess.PIPE,
                                     text=True)
        assert self.proc.stdout is not None
        self.path = self.proc.stdout.readline().strip()
        self.events: queue.Queue[dict] = queue.Queue()
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.events.put(json.loads(line))

    def wait_event(self, name: str, timeout: float = 10.0) -> dict:
        end = time.monotonic() + timeout
        while True:
            ev = self.events.get(timeout=max(0.01, end - time.monotonic()))
            if ev["event"] == name:
                return ev

    def stop(self) -> None:
        self.proc.send_signal(signal.SIGTERM)
        self.proc.wait(timeout=5)


def host_killed() -> float:
    """Seconds from SIGKILL of a streaming host to the device's watchdog trip."""
    emu = Emu()
    host = subprocess.Popen([sys.executable, "-c", HOST, emu.path], cwd=ROOT,
                            stdout=subprocess.PIPE, text=True)
    try:
        assert host.stdout is not None and host.stdout.readline().strip() == "moving"
        emu.wait_event("armed")
        t_kill = time.monotonic()
        os.kill(host.pid, signal.SIGKILL)
        host.wait(timeout=5)
        return emu.wait_event("watchdog_tripped")["t"] - t_kill
    finally:
        if host.poll() is None:
            host.kill()
        emu.stop()


def wire_cut() -> tuple[float, float] | None:
    """(cut -> host's link lost, cut -> watchdog trip) in seconds; None if the link was lost
    before the cut."""
    emu = Emu("--disconnect-after", "1.0", "--disconnect-for", "0.5")
    hw = SerialHardware(BridgeConfig.from_robot(EXT), emu.path)
    try:
        assert hw.configure() is ReturnType.OK and hw.activate() is ReturnType.OK, hw.fault
        target = np.full(6, 100000)
        period = hw.config.period_s
        nxt, end = time.perf_counter(), time.perf_counter() + 5.0
        while time.perf_counter() < end:
            if hw.read() is ReturnType.ERROR or hw.write(target) is ReturnType.ERROR:
                break
            nxt += period
            time.sleep(max(0.0, nxt - time.perf_counter()))
        t_err = time.monotonic()
        cut = emu.wait_event("link_cut")["t"]
        if t_err < cut:
            return None
        return t_err - cut, emu.wait_event("watchdog_tripped")["t"] - cut
    finally:
        hw.cleanup()
        emu.stop()


def _row(name: str, ms: list[float], least_ms: float) -> str:
    if not ms:
        return f"{name:<26}{'-':>10}{'-':>10}{least_ms:>14.0f}"
    return f"{name:<26}{np.median(ms):10.1f}{max(ms):10.1f}{least_ms:>14.0f}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=5)
    args = ap.parse_args(argv)
    cfg = BridgeConfig.from_robot(EXT)
    period_ms = cfg.period_s * 1000
    kills = [host_killed() * 1000 for _ in range(args.trials)]
    cuts = [wire_cut() for _ in range(args.trials)]
    timed = [c for c in cuts if c is not None]
    print(f"{args.trials} trials each; watchdog {cfg.watchdog_s * 1000:.0f} ms, host link timeout "
          f"{cfg.link_timeout_s * 1000:.0f} ms, period {period_ms:.0f} ms; "
          f"{len(cuts) - len(timed)} cut trial(s) lost the link before the cut")
    print(f"{'':26}{'p50 ms':>10}{'max ms':>10}{'baseline ms':>14}")
    print(_row("host killed -> trip", kills, cfg.watchdog_s * 1000 + period_ms))
    print(_row("wire cut -> host lost", [c[0] * 1000 for c in timed],
               cfg.link_timeout_s * 1000 + period_ms))
    print(_row("wire cut -> trip", [c[1] * 1000 for c in timed],
               cfg.watchdog_s * 1000 + period_ms))
    return 0


if __name__ == "__main__":
    sys.exit(main())
