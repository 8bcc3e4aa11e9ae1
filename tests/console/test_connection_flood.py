"""A scaled-down connection flood on the default soft console (serve.py's build, mock device):
every browser that closes leaves nothing behind, and STOP works during the flood.

Independent expectations: the per-browser state of viser (its client list, connection states,
broadcast cursors) and of the console (the connection gate, the client guard, the Session
panel's widgets and replay sessions, the viewer lines, the window fit) is back to what it was
before the flood; the process's RSS back within 10 % of it (after a warm-up: the allocator's
arenas grow once); the process's threads back to their number (viser's callback threads end
when idle, ``console.web.callback_pool``); the log has no traceback; a viewer's STOP during the
flood counts one STOP. The waits wait for those states with generous deadlines: how soon they
come, and what the flood costs beside a bare viser server, is ``benchmarks/connection_flood.py``.
"""

from __future__ import annotations

import logging
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import pytest

from console.panels.common.session import SessionPanel
from console.web.callback_pool import IdleThreadPool
from console.web.connection_gate import release_free_memory
from tests.ws_client import RawClient, wait_for

CYCLES, HELD = 100, 40
TESTS = Path(__file__).resolve().parents[1]


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise AssertionError("no VmRSS")


def thread_names() -> list[str]:
    return sorted(t.name for t in threading.enumerate())


def per_browser(app: Any) -> dict[str, int]:
    ws = app.server._websock_server
    return {
        "viser clients": len(app.server.get_clients()),
        "connection states": len(ws._client_state_from_id),
        "live connections": len(ws._live_connections),
        "broadcast cursors": len(ws._broadcast_buffer.generator_cursors),
        "gate admitted": app.connections.admitted,
        "guard clients": len(app.guard._clients),
        "session widgets": len(app.panel(SessionPanel).clients),
        "replay sessions": len(app.panel(SessionPanel).player.all()),
        "viewer lines": len(app.viewer_line._lines),
        "window fits": len(app.window_fit._framed),
    }


FLOOD = """
import sys
import threading
sys.path.insert(0, sys.argv[1])
from ws_client import drain, viewer_socket

port, cycles, held = (int(a) for a in sys.argv[2:5])


def drain_all(sockets, stop):  # reads (and drops) what the held viewers get, as a browser would
    while not stop.is_set():
        for ws in sockets:
            drain(ws)
        stop.wait(0.05)


for k in range(cycles):
    viewer_socket(port, f"127.0.0.{2 + k % 20}").close()
sockets = [viewer_socket(port, f"127.0.0.{30 + k % 4}") for k in range(held)]
stop = threading.Event()
reader = threading.Thread(target=drain_all, args=(sockets, stop))
reader.start()
print("held", flush=True)
sys.stdin.readline()
stop.set()
reader.join()
for ws in sockets:
    ws.close()
print("closed", flush=True)
"""


class Flood:
    """``cycles`` viewers opened and closed one after another, then ``held`` opened and held
    (reading what they get), from a process of its own (a client in this process would count
    its memory and threads in the server's); :meth:`release` closes the held ones."""

    def __init__(self, port: int, cycles: int, held: int) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-c", FLOOD, str(TESTS), str(port), str(cycles), str(held)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        assert self.proc.stdout is not None
        self._expect("held")

    def _expect(self, word: str) -> None:
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        assert line.strip() == word, f"the flood process said {line!r}, not {word!r}"

    def release(self) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write("close\n")
        self.proc.stdin.flush()
        self._expect("closed")
        self.proc.wait(30)

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(30)


@pytest.mark.slow(10)
def test_a_flood_of_connections_leaves_nothing_behind_and_stop_works_during_it(
        served_console: Any, caplog: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(IdleThreadPool, "idle_s", 0.5)  # (5 s in serve.py)
    app = served_console("soft-arm", "mock", "--lab")
    server = app.server
    port = server.get_port()
    caplog.set_level(logging.WARNING)
    # A viewer's STOP starts what a STOP starts once (the control process's command queue's
    # feeder thread): the threads to come back to are counted after it.
    watcher = RawClient(server, source="127.0.0.41")
    stops = app.stops
    assert watcher.update(app.header.stop_btn._impl.uuid, value=True)
    wait_for(lambda: app.stops == stops + 1, timeout=30.0, what="the first STOP")
    watcher.close()
    del watcher
    wait_for(lambda: per_browser(app)["viser clients"] == 0 and not any(
        n.startswith("viser-callback") for n in thread_names()),
             timeout=60.0, what="the first viewer gone and viser's callback threads ended")
    threads0 = thread_names()
    # Warm-up: the allocator's arenas grow once, the first time browsers come and go.
    Flood(port, 30, 5).release()
    wait_for(lambda: per_browser(app)["viser clients"] == 0, timeout=30.0, what="warm-up closed")
    release_free_memory()
    before, rss0 = per_browser(app), rss_mb()

    flood = Flood(port, CYCLES, HELD)
    try:
        watcher = RawClient(server, source="127.0.0.40")
        wait_for(lambda: per_browser(app)["session widgets"] == HELD + 1, timeout=60.0,
                 what=lambda: f"{HELD + 1} viewers set up (now {per_browser(app)})")
        stops = app.stops
        assert watcher.update(app.header.stop_btn._impl.uuid, value=True)
        wait_for(lambda: app.stops == stops + 1, timeout=30.0, what="a viewer's STOP")
        assert per_browser(app)["viser clients"] == HELD + 1
        watcher.close()
        del watcher
        flood.release()
    finally:
        flood.kill()
    wait_for(lambda: per_browser(app) == before, timeout=30.0,
             what=lambda: f"per-browser state back to {before} (now {per_browser(app)})")
    wait_for(lambda: thread_names() == threads0, timeout=60.0,
             what=lambda: f"threads back to {threads0} (now {thread_names()})")
    wait_for(lambda: rss_mb() <= 1.10 * rss0, timeout=60.0,
             what=lambda: f"RSS within 10 % of {rss0:.1f} MB (now {rss_mb():.1f})")
    tracebacks = [r for r in caplog.records if r.exc_info is not None]
    assert not tracebacks, [r.getMessage() for r in tracebacks]
