"""What reading the newest motion-capture frame costs the 100 Hz loop, beside a blocking read.

The loop asks its mocap source for the newest frame every tick; :class:`hw_bridge.mocap.
UdpMocapReceiver` receives on its own thread, so ``latest()`` is a plain read that never waits
for the network (tests/hw_bridge/test_hw_mocap.py checks that it returns with nothing sent; its
duration is this figure). Rows, in the same run, while a sender streams frames at ``--rate`` Hz
over loopback:

* **latest()**: ``UdpMocapReceiver.latest()`` (ours);
* **baseline recv**: what a loop reading the socket itself would wait: ``recv`` on a socket with
  a 5 ms timeout (one tick's budget is 10 ms), the frame or the timeout, whichever comes first.

``python benchmarks/mocap_latest.py [--calls 2000] [--rate 240]``; prints p50 / p99 / max in us.
"""

from __future__ import annotations

import argparse
import socket
import sys
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from hw_bridge.mocap import UdpMocapReceiver, encode_mocap_packet  # noqa: E402


def _sender(addrs: list[tuple[str, int]], rate: float, stop: threading.Event) -> None:
    """Stream frames at ``rate`` Hz to every address until ``stop``."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    pts, seq, period = np.zeros((7, 3)), 0, 1.0 / rate
    nxt = time.monotonic()
    while not stop.is_set():
        seq += 1
        for a in addrs:
            s.sendto(encode_mocap_packet(seq, time.monotonic(), pts, True), a)
        nxt += period
        time.sleep(max(0.0, nxt - time.monotonic()))
    s.close()


def _row(name: str, us: np.ndarray) -> str:
    return (f"{name:<16} p50 {np.percentile(us, 50):9.1f} us   p99 {np.percentile(us, 99):9.1f} us"
            f"   max {us.max():9.1f} us")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=2000)
    ap.add_argument("--rate", type=float, default=240.0, help="frames per second sent")
    args = ap.parse_args(argv)
    rx = UdpMocapReceiver(0)
    rx.start()
    raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    raw.bind(("127.0.0.1", 0))
    raw.settimeout(0.005)
    stop = threading.Event()
    sender = threading.Thread(target=_sender, args=([rx.addr, raw.getsockname()], args.rate,
                                                    stop), daemon=True)
    sender.start()
    ours, base = np.empty(args.calls), np.empty(args.calls)
    try:
        for i in range(args.calls):
            t0 = time.perf_counter()
            rx.latest()
            ours[i] = time.perf_counter() - t0
            t0 = time.perf_counter()
            try:
                raw.recv(65536)
            except socket.timeout:
                pass
            base[i] = time.perf_counter() - t0
    finally:
        stop.set()
        sender.join(timeout=1.0)
        rx.stop()
        raw.close()
    print(f"{args.calls} calls, frames at {args.rate:.0f} Hz over loopback; "
          f"{rx.frames} frames received by latest()'s thread")
    print(_row("latest()", ours * 1e6))
    print(_row("baseline recv", base * 1e6))


if __name__ == "__main__":
    main()
