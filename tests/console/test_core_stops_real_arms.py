"""A console built with no panels at all still moves the arm from the store and stops it on STOP
and on a lost lease, for both arms, with the real loop processes (the soft arm's control process
on its simulated arm, the extensible arm's runner process on its in-process mock), and a killed
loop process stops motion once: what stops the arm no longer depends on which panels were
built."""

from __future__ import annotations

import time
from typing import Any, Callable

import numpy as np

from console.app import ConsoleApp
from console.core.access import AccessControl
from console.core.model import model_for
from console.core.services import ConsoleServices
from console.core.state import StateStore
from core.kinematics import delta as dk
from core.robots import load
from hw_bridge.extensible_process import ExtensibleProcess
from hw_bridge.soft_arm_process import ControlProcess

SOFT = load("soft-arm")
EXT = load("extensible")


def wait_for(pred: Callable[[], Any], timeout: float = 30.0, what: str = "") -> None:
    end = time.monotonic() + timeout
    while not pred():
        assert time.monotonic() < end, f"timed out waiting for {what}"
        time.sleep(0.02)


def still(read: Callable[[], np.ndarray], seconds: float = 0.5) -> bool:
    """Whether ``read()`` (the arm as the loop publishes it) stays where it is."""
    before = np.array(read())
    time.sleep(seconds)
    return bool(np.allclose(read(), before, atol=1e-9))


def test_the_soft_arm_without_panels_jogs_from_the_store_and_stops_on_stop_and_lease_loss(
        server: Any) -> None:
    ctl = ControlProcess(SOFT, device="sim", sched_priority=None, cpus=None)
    app = ConsoleApp(SOFT, server, panels=(), access=AccessControl(None),
                     services=ConsoleServices(soft_control=ctl))
    app.core.start()  # (not the lease monitor: "Ann" has no browser that could answer it)
    control = lambda: ctl.view.snapshot.control  # noqa: E731
    try:
        wait_for(lambda: ctl.view is not None and control() is not None, 60, "the loop")
        for event in ("STOP", "lease"):
            ctl.arm().result(20)
            wait_for(lambda: control().armed and control().phase == "idle"
                     and control().kappa_meas is not None, what="armed and idle")
            app.access.take(1, name="Ann")
            app.store.request(np.full(SOFT.n_segments, 6.0), "jog")  # no panel forwards it
            wait_for(lambda: control().kappa_ref[0] > 1.0, what="moving to the jog")
            if event == "STOP":
                app.stop_motion("STOP pressed by Bob")
            else:
                app.access.revoke("Ann's tab went silent for 3 s", 1)
            wait_for(lambda: control().phase == "stopped", what=f"stopped by {event}")
            assert control().reason == app.last_stop.reason  # type: ignore[union-attr]
            assert still(lambda: control().commands)  # the cylinders' volumes are frozen
        assert app.stops == 2 and "silent" in app.last_stop.reason  # type: ignore[union-attr]
    finally:
        app.stop()
        ctl.close()


def test_the_extensible_arm_without_panels_follows_the_store_and_stops_on_stop_and_lease_loss(
        server: Any) -> None:
    store = StateStore(model_for(EXT), mirror_commands=True)
    runner = ExtensibleProcess(EXT, store, "mock", cpus=None, sched_priority=None)
    app = ConsoleApp(EXT, server, panels=(), access=AccessControl(None), store=store,
                     services=ConsoleServices(extensible_runner=runner))
    app.core.start()  # (not the lease monitor: "Ann" has no browser that could answer it)
    tip = lambda: runner.snapshot.measured_tip  # noqa: E731
    try:
        runner.start()
        wait_for(lambda: runner.snapshot.state == "disarmed", 60, "connected, disarmed")
        runner.bridge_controls.arm()
        wait_for(lambda: runner.snapshot.state == "holding" and tip() is not None, what="armed")
        app.access.take(1, name="Ann")
        q = np.asarray(store.command.q, float)
        for event in ("STOP", "lease"):
            far = q.copy()
            far[:, 2] += 0.08  # racks out by 80 mm: ~0.5 s (it is stopped long before)
            goal = dk.tip_position(EXT, far)
            store.request(far, "jog")  # no panel and no pump: the core sends the set-point
            wait_for(lambda: runner.snapshot.state == "following", what="following the jog")
            if event == "STOP":
                app.stop_motion("STOP pressed by Bob")
            else:
                app.access.revoke("Ann's tab went silent for 3 s", 1)
                app.access.take(1, name="Ann")
            wait_for(lambda: runner.snapshot.state == "holding", what=f"holding after {event}")
            wait_for(lambda: still(tip, 0.3), what="the measured tip at rest")  # it holds ...
            assert np.linalg.norm(tip() - goal) > 0.005  # ... short of the jog's goal
            q = np.asarray(store.command.q, float)
        assert app.stops == 2 and "silent" in app.last_stop.reason  # type: ignore[union-attr]
    finally:
        app.stop()
        runner.close()


def test_a_killed_loop_process_stops_motion_once_with_why(server: Any) -> None:
    """The watcher: the soft arm's control process killed mid-jog ends motion through the one
    route, once, naming why it died (jogging ends: nothing more is commanded)."""
    ctl = ControlProcess(SOFT, device="sim", sched_priority=None, cpus=None)
    app = ConsoleApp(SOFT, server, panels=(), access=AccessControl(None),
                     services=ConsoleServices(soft_control=ctl))
    app.core.start()
    try:
        wait_for(lambda: ctl.view is not None, 60, "the loop")
        app.access.take(1, name="Ann")
        assert app.core.hold.move_to(1, np.full(SOFT.n_segments, 3.0))  # a set-point move
        ctl._proc.kill()
        wait_for(lambda: app.stops == 1, what="the watcher's stop")
        assert app.last_stop.reason.startswith("control loop died: ")  # type: ignore[union-attr]
        assert not app.core.hold.active
        time.sleep(0.3)  # (the watcher ticks every 20 ms)
        assert app.stops == 1
    finally:
        app.stop()
        ctl.close()
