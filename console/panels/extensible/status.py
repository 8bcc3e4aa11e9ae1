"""What the extensible arm's panels say about its link and its runner, from one source each.

:func:`link_summary` words the link supervisor's health as the Hardware panel and the header's
Link field do (``console.panels.common.hardware.header_link``); :func:`runner_phase` is the header's
Phase field (idle, moving to target, running path t/T s, holding after STOP, fault), pushed by
the Paths panel; :func:`hardware_html` is the Paths panel's "Hardware:" line (that link and
the runner's state); :func:`extensible_runner` is the runner the Paths and Repeatability panels
drive and :func:`extensible_arm` the robot they are built for, typed. The worker process they
plan and solve in: :mod:`console.panels.extensible.worker_pool`.
"""

from __future__ import annotations

import html
from typing import Any

from console.panels.common.header import Tone
from console.panels.common.hardware import extensible_link_health, header_link
from core.robots import ExtensibleArm
from hw_bridge.extensible_jobs import RunnerSnapshot
from hw_bridge.extensible_process import ExtensibleProcess


def extensible_runner(app: Any) -> ExtensibleProcess:
    """``app.services.extensible_runner``, or a clear error when the console was built without
    one (serve.py always builds it for the extensible arm)."""
    runner = app.services.extensible_runner
    if runner is None:
        raise ValueError("the extensible arm's panels need its runner: build the console with "
                         "services=ConsoleServices(extensible_runner=...) (serve.py does)")
    return runner


def extensible_arm(app: Any) -> ExtensibleArm:
    """``app.robot`` as the extensible arm these panels are built for (their ``kinds`` keep them
    off the soft arm), or a clear error on another robot: the one place the type is checked."""
    robot = app.robot
    if not isinstance(robot, ExtensibleArm):
        raise TypeError(f"the extensible arm's panels need an extensible arm, not "
                        f"{type(robot).__name__}")
    return robot


def link_summary(app: Any) -> str:
    """The extensible arm's link in words, from the link supervisor's health: the Hardware
    panel's controls, or (in-process mock) the runner's own link once it runs."""
    attachment = app.services.hardware
    kind = None if attachment is None else attachment.kind
    health = extensible_link_health(app)
    text = header_link(kind, health)[0]
    if health is None and kind == "mock":
        text += " (the in-process mock starts on the first Execute or Reconnect)"
    return text


def hardware_html(app: Any, text: str | None = None) -> str:
    """The link as the Hardware panel and the header's Link field show it (the link
    supervisor's health), and the runner's state once it runs."""
    if text is None:
        text = link_summary(app)
        runner = app.services.extensible_runner
        if runner is not None and runner.started:
            snap = runner.snapshot
            text += f" · runner {snap.state}" + (f" · ⚠ {snap.fault}" if snap.fault else "")
    return (f'<div data-testid="path-hardware" style="font-size:0.8em;opacity:.8">'
            f"Hardware: {html.escape(text)}</div>")


def runner_phase(snap: RunnerSnapshot | None, period_s: float, job: int, moving: bool,
                 stopped: bool) -> tuple[str, Tone]:
    """The Phase field: ``snap`` the runner's snapshot (None: not started), ``job`` the Paths
    panel's job id, ``moving`` whether ``app.core.hold`` moves to a set-point (target, slider),
    ``stopped`` whether STOP held the arm since its last motion."""
    if snap is not None and snap.fault:
        return f"fault: {snap.fault}", "fault"
    if snap is not None and snap.busy:
        if snap.job_id == job and snap.n_samples > 1:
            total = (snap.n_samples - 1) * period_s  # samples at the loop's rate
            done = min(total, snap.sample * period_s)
            return f"running path {done:.1f}/{total:.1f} s", "busy"
        return f"running {snap.label or 'a move'}", "busy"
    if moving or (snap is not None and snap.state == "following"):
        return "moving to target", "busy"
    if stopped:
        return "holding after STOP", "warn"
    return "idle", "ok"
