"""The operator's lease probes while another browser floods the console: gaps and admitted rate.

Issue 14: before the client guard, a burst of 10 000 STOP clicks from one client delayed the
operator's lease probe by 8-9 s (the lease is 7 s: the operator lost control). The flood tests
(``tests/console/test_client_guard_flood.py``) check the behaviour on the guard's stopped clock
(exactly ``burst`` messages admitted, only the sender disconnected, the operator keeps control);
the wall-clock figures live here:

* the gaps between the operator's probe answers (server side, ``AccessControl.heartbeat``) in a
  quiet ``--seconds`` window first (the baseline), then from the start of each flood until
  ``--seconds`` after it;
* how long the guard took to disconnect the sender (from its first message), how many of its
  messages it admitted meanwhile (its limit: ``burst`` at once, then ``GuardLimits.rate`` per
  second), and when the sender's socket saw the close (the close handshake waits behind the
  frames it still has to read: up to websockets' 10 s close timeout).

A lab console (``ConsoleApp`` with the Session panel and the default panels, probing every
0.1 s as while jogging), raw websocket clients (``tests/ws_client.py``): an operator answering
the probes like a tab, and one flooding client per flood. Prints a table (s) and, with
``--json``, one JSON line.

``python benchmarks/flood_probe_gaps.py [--seconds 3] [--json]``
"""

from __future__ import annotations

import argparse
import json
import secrets
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))


class Answers:
    """Server-side times of the holder's probe answers (wraps ``AccessControl.heartbeat``)."""

    def __init__(self, access: Any) -> None:
        self.lock = threading.Lock()
        self.times: list[float] = []
        original = access.heartbeat

        def heartbeat(client: Any) -> bool:
            ok = original(client)
            if ok:
                with self.lock:
                    self.times.append(time.monotonic())
            return ok

        access.heartbeat = heartbeat

    def gaps(self, start: float, end: float) -> np.ndarray:
        """Gaps (s) between consecutive answers in [start, end], counting from ``start``."""
        with self.lock:
            ts = [t for t in self.times if start <= t <= end]
        return np.diff(np.array([start, *ts, end]))


def summary(gaps: np.ndarray) -> dict[str, float]:
    """Median, 99th percentile and worst gap (s), and the number of answers."""
    return {"n": int(len(gaps) - 1), "p50": float(np.percentile(gaps, 50)),
            "p99": float(np.percentile(gaps, 99)), "max": float(gaps.max())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=3.0,
                    help="the baseline window, and the window after each flood's start")
    ap.add_argument("--json", action="store_true", help="print one JSON line too")
    args = ap.parse_args()

    import msgspec
    import viser

    from console import web
    from console.app import ConsoleApp
    from console.core.access import AccessControl
    from console.panel_sets import DEFAULT_PANELS
    from console.panels.common.session import SessionPanel
    from core.robots import load
    from ws_client import CAMERA, RawClient, wait_for

    web.install()
    token = secrets.token_urlsafe(9)
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    with tempfile.TemporaryDirectory() as data:
        app = ConsoleApp(load("soft-arm"), server, panels=(*DEFAULT_PANELS, SessionPanel),
                         access=AccessControl(token), data_dir=Path(data))
        app.lease.busy = lambda: True  # probed every 0.1 s, as while jogging
        answers = Answers(app.access)
        app.start()
        try:
            session = app.panel(SessionPanel)
            op = RawClient(server)
            wait_for(lambda: op.client_id in session.clients, 60.0, "operator's widgets")
            app.access.take(op.client_id, token, "Olivia")
            wait_for(lambda: len(answers.times) > 3, 60.0, "the operator answering")
            t0 = time.monotonic()
            time.sleep(args.seconds)
            rows: dict[str, dict[str, float]] = {
                "baseline (no flood)": summary(answers.gaps(t0, time.monotonic()))}
            stop_uuid = app.header.stop_btn._impl.uuid
            floods = {
                "10000 STOP clicks": (msgspec.msgpack.encode(
                    {"type": "GuiUpdateMessage", "uuid": stop_uuid, "updates": {"value": True}}),
                    10_000),
                "5000 camera messages": (msgspec.msgpack.encode(CAMERA.as_serializable_dict()),
                                         5_000)}
            for name, (frame, count) in floods.items():
                sender = RawClient(server)
                wait_for(lambda: sender.client_id in session.clients, 60.0, "sender's widgets")
                counts = app.guard.counts
                accepted0, disconnected0 = counts["accepted"], counts["disconnected"]
                n_answers0 = len(answers.times)
                start = time.monotonic()
                judged: list[float] = []

                def watch() -> None:  # the guard's verdict, polled every millisecond
                    while counts["disconnected"] == disconnected0:
                        if time.monotonic() - start > 60.0:
                            return
                        time.sleep(0.001)
                    judged.append(time.monotonic() - start)

                watcher = threading.Thread(target=watch, daemon=True)
                watcher.start()
                for _ in range(count):
                    if not sender.send(frame):
                        break
                watcher.join(61.0)
                admitted = (counts["accepted"] - accepted0) - (len(answers.times) - n_answers0)
                sender.wait_closed(60.0)
                closed = time.monotonic() - start
                time.sleep(max(0.0, args.seconds - closed))
                row = summary(answers.gaps(start, time.monotonic()))
                row.update(disconnect_s=judged[0] if judged else float("nan"),
                           admitted=float(admitted), socket_closed_s=closed)
                rows[name] = row
            holder = app.access.holder
            kept = holder is not None and holder.client_id == op.client_id
        finally:
            app.stop()
            server.stop()

    lim = app.guard.limits
    print(f"Operator's probe answers (probed every {app.lease.probe_period:g} s; lease "
          f"{app.access.lease_s:g} s); guard limit {lim.rate:g} msg/s, burst {lim.burst:g}")
    print(f"{'window':24s} {'answers':>7s} {'p50 s':>7s} {'p99 s':>7s} {'max s':>7s} "
          f"{'disconnect s':>12s} {'admitted':>8s} {'closed s':>8s}")
    for name, r in rows.items():
        extra = (f"{r['disconnect_s']:12.3f} {r['admitted']:8.0f} {r['socket_closed_s']:8.2f}"
                 if "disconnect_s" in r else "")
        print(f"{name:24s} {r['n']:7d} {r['p50']:7.3f} {r['p99']:7.3f} {r['max']:7.3f} {extra}")
    print(f"operator kept control: {kept}")
    if args.json:
        print(json.dumps({"rows": rows, "kept_control": kept}))


if __name__ == "__main__":
    main()
