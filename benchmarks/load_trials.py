"""Trials back to back for the load benchmark, counted so a run whose arm stood still shows it."""

from __future__ import annotations

import dataclasses
import threading
import time
from typing import Any


@dataclasses.dataclass
class TrialTally:
    """What the back-to-back trials did (so a run whose arm stood still shows it)."""

    started: int = 0
    released: int = 0
    stopped: int = 0
    refused: int = 0
    last_stop: str = ""


RUNNING = ("settling", "planning", "approach", "grasp", "move_to_bin", "release")


def start_trials(app: Any, robot: Any, stop: threading.Event) -> tuple[Any, TrialTally]:
    """Grasp-and-place trials back to back on the console's control process (None if absent).

    The soft arm's 100 Hz loop runs in ``app.services.soft_control`` (a ``ControlProcess``: its own
    process, attached by ``serve.build``); the Control panel draws what it measures. A trial
    that stops (a link fault, a lost object) is counted with its reason; the next one arms
    again, as an operator would.
    """
    tally = TrialTally()
    ctl = app.services.soft_control
    if ctl is None:
        return None, tally
    from core.control.trials import paper_locations

    spots = list(paper_locations().values())
    r0 = robot.capture.nominal_object_radius
    ctl.arm().result(30)

    def phase() -> Any:
        view = ctl.view
        return None if view is None else view.snapshot.control

    def trials() -> None:
        i = 0
        while not stop.is_set():
            x, y = spots[i % len(spots)]
            i += 1
            try:
                c = phase()
                if c is None or not c.armed:  # after a fault: arm again, as an operator would
                    ctl.arm().result(30)
                ctl.grasp_at(x, y, r0).result(30)
            except Exception as exc:  # noqa: BLE001 - a refused trial: note it, go on
                tally.refused += 1
                tally.last_stop = f"refused: {exc}"
                stop.wait(1.0)
                continue
            tally.started += 1
            running, c = False, None
            deadline = time.monotonic() + 120.0
            while not stop.wait(0.1) and time.monotonic() < deadline:
                c = phase()  # (the view may still show the previous trial's end at first)
                if c is not None and c.phase in RUNNING:
                    running = True
                elif running and c is not None and c.phase in ("released", "stopped"):
                    break
            if c is not None and c.phase == "released":
                tally.released += 1
            elif not stop.is_set():
                tally.stopped += 1
                tally.last_stop = (c.reason or c.phase) if c is not None else "no telemetry"
            try:
                ctl.goto([0.0] * robot.n_segments).result(30)
            except Exception as exc:  # noqa: BLE001 - e.g. disarmed by a fault: next trial arms
                tally.last_stop = f"{tally.last_stop}; return refused: {exc}"
            stop.wait(1.0)

    threading.Thread(target=trials, name="bench-trials", daemon=True).start()
    return ctl, tally


def trials_in(first: dict[str, Any], last: dict[str, Any]) -> dict[str, Any]:
    """The trial counts between two stats samples (and the latest stop reason)."""
    out = {k: last[k] - first[k] for k in ("started", "released", "stopped", "refused")}
    out["last_stop"] = last["last_stop"]
    return out


def trials_text(first: dict[str, Any], last: dict[str, Any]) -> str:
    t = trials_in(first, last)
    why = f" (last: {t['last_stop']})" if t["stopped"] or t["refused"] else ""
    return (f"trials {t['released']} released / {t['started']} started, {t['stopped']} stopped, "
            f"{t['refused']} refused{why}")
