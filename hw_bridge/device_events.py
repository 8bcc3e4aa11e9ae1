"""Where the device emulator's events go, so a watchdog trip after a host crash is not lost.

The emulator writes its JSON events to stdout, which its host (the control process) pumps. When
the host dies - even by SIGKILL - nobody reads that pipe any more, yet that is exactly when the
operator needs to know what the device did. So:

* :class:`hw_bridge.emulator.EventSink` also appends every event (with the wall-clock time) to a JSON-lines log
  file (``HW_BRIDGE_EVENT_LOG``; the console sets ``<data-dir>/device-events.jsonl``) and
  prints the important ones (watchdog trip, host gone) on stderr, i.e. the terminal of
  ``serve.py``; a closed stdout is tolerated.
* :class:`HostWatch` (polled by the emulator's loop): once its parent is gone (pid from
  ``HW_BRIDGE_PARENT_PID``, :mod:`hw_bridge.parent_watch`) it logs ``host_gone``, waits for the
  watchdog to trip (armed: within ``watchdog_ms``; at most ``trip_wait_s``), logs
  ``host_gone_exit`` with the outcome and asks the loop to stop - well within 1 s.
* :func:`unreported_host_losses` lets the console say at its next start what happened.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

from hw_bridge.parent_watch import parent_gone, parent_pid_from_env

EVENT_LOG_ENV = "HW_BRIDGE_EVENT_LOG"
EVENT_LOG_NAME = "device-events.jsonl"
LOUD_EVENTS = frozenset({"watchdog_tripped", "host_gone", "host_gone_exit"})
_MAX_TAIL_BYTES = 256 * 1024
_ROTATE_BYTES = 16 * 1024 * 1024


def describe_event(ev: dict[str, Any]) -> str:
    name = ev.get("event")
    if name == "watchdog_tripped":
        return "WATCHDOG TRIPPED - no demand from the host in time; motors stopped"
    if name == "host_gone":
        return (f"its host process (pid {ev.get('parent')}) died; "
                + ("armed: waiting for the watchdog" if ev.get("armed") else "not armed"))
    if name == "host_gone_exit":
        if ev.get("watchdog_tripped"):
            return (f"watchdog tripped {ev.get('after_ms')} ms after the host died; motors "
                    "stopped; emulator exiting")
        return "host died while the device was not armed (motors idle); emulator exiting"
    return json.dumps(ev)


class HostWatch:
    """The emulator's parent-death watch, polled from its loop (no thread of its own)."""

    def __init__(self, sink: Any, parent_pid: int | None = None, trip_wait_s: float = 0.3):
        self.sink = sink
        self.parent = parent_pid_from_env() if parent_pid is None else parent_pid
        self.trip_wait_s = trip_wait_s
        self.gone_at: float | None = None
        self.armed_when_gone = False

    def poll(self, now: float, core: Any) -> bool:
        """Returns True when the emulator should exit (host gone, trip logged or timed out)."""
        if self.parent is None:
            return False
        if self.gone_at is None:
            if not parent_gone(self.parent):
                return False
            self.gone_at = now
            self.armed_when_gone = bool(core.armed or core.tripped)
            self.sink.emit("host_gone", parent=self.parent, armed=self.armed_when_gone)
        waited = now - self.gone_at
        if core.armed and not core.tripped and waited < self.trip_wait_s:
            return False
        self.sink.emit("host_gone_exit", parent=self.parent, armed=self.armed_when_gone,
                       watchdog_tripped=bool(core.tripped), after_ms=round(waited * 1000, 1))
        return True


def unreported_host_losses(log_path: Path) -> list[dict[str, Any]]:
    """``host_gone_exit`` records after the last ``console_start`` marker; then adds one.

    Called once by the console at start-up; reads only the file's last 256 kB. A log past
    ``_ROTATE_BYTES`` is renamed to ``<name>.1`` (replacing the one before) after reading.
    """
    found: list[dict[str, Any]] = []
    size = 0
    try:
        with open(log_path, "rb") as f:
            f.seek(0, os.SEEK_END)
            size = f.tell()
            f.seek(max(0, size - _MAX_TAIL_BYTES))
            tail = f.read().decode("utf-8", "replace").splitlines()
    except OSError:
        tail = []
    for line in tail:
        try:
            ev = json.loads(line)
        except ValueError:
            continue
        if not isinstance(ev, dict):
            continue
        if ev.get("event") == "console_start":
            found = []
        elif ev.get("event") == "host_gone_exit":
            found.append(ev)
    try:
        if size > _ROTATE_BYTES:
            os.replace(log_path, f"{log_path}.1")
    except OSError:
        pass
    try:
        with open(log_path, "a", encoding="utf-8") as f:
            f.write(json.dumps({"event": "console_start", "wall": time.strftime(
                "%Y-%m-%dT%H:%M:%S%z"), "pid": os.getpid()}) + "\n")
    except OSError:
        pass
    return found


def describe_loss(ev: dict[str, Any]) -> str:
    """One line for the console: what the device did when its previous host died."""
    when = ev.get("wall", "?")
    if ev.get("watchdog_tripped"):
        return (f"At {when} the previous console's control process died while the arm was "
                f"armed; the device watchdog tripped {ev.get('after_ms')} ms later and stopped "
                "the motors.")
    if ev.get("armed"):
        return (f"At {when} the previous console's control process died while the arm was "
                "armed; the device watchdog did NOT report a trip.")
    return f"At {when} the previous console's control process died (the arm was not armed)."
