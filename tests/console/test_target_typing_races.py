"""The tip target takes every typed field, whatever the panel's other threads do meanwhile.

Typing only sets the pending target (nothing is submitted); Go submits all three fields.

A browser's x, y, z arrive as three messages; viser stores each value, then runs its callback in
its thread pool, so two field callbacks may run at once, and the render thread may answer a new
command (the runner's posture on Arm: the target rides on the tip) at the same moment. Before,
the target panel read the fields, then said "Solving…" and submitted the target in steps another
thread could come between: a callback that read (x, old z) could submit after the one that read
(x, z), and a tip reset between a read and its "Solving…" was echoed over the typed x. A console
test lost a typed z (the arm went to (100, 0, 460) for (100, 0, 300)) and a typed x so, on a
loaded machine. Here the first callback is held right after it read the fields, the others are
let run meanwhile; nothing is submitted by typing, and the target Go submits must hold every
typed field.
"""

from __future__ import annotations

import dataclasses
import threading
from typing import Any

import numpy as np
from fakes import FakeClient, FakeRunner, console_app, user

from console.core.access import AccessControl
from core.robots import load

EXT = load("extensible")


@dataclasses.dataclass
class FakeHardware:
    kind: str


def test_typed_fields_reach_the_target_past_a_concurrent_field_and_a_tip_reset(server: Any):
    from console.panels.extensible.target import TargetPanel

    app = console_app(EXT, server, panels=(), extensible_runner=FakeRunner(),
                      hardware=FakeHardware("mock"), access=AccessControl("tok"))
    try:
        panel = app.add_panel(TargetPanel)
        submitted: list[np.ndarray] = []
        panel.worker.submit = lambda target, *a: submitted.append(np.array(target) * 1e3)
        op = FakeClient(7)
        app.access.take(op.client_id, "tok", name="Alice")
        x_in, y_in, z_in = panel.inputs
        y0, z0 = float(y_in.value), float(z_in.value)
        typed = (100.0, y0, z0 - 160.0)

        read, go = threading.Event(), threading.Event()
        real_read = panel._typed.read

        def held_read(*args: Any) -> list[float]:
            values = real_read(*args)
            if threading.current_thread().name == "x":
                read.set()
                assert go.wait(30)
            return values

        panel._typed.read = held_read  # type: ignore[method-assign]
        x_thread = threading.Thread(target=user, args=(x_in, op, typed[0]), name="x")
        x_thread.start()  # x's callback: reads (100, y0, z0), then is held
        assert read.wait(30)
        # Meanwhile: the runner makes its posture the command (a new command the render thread
        # answers by putting the target on the tip) and z is typed (stored, its callback runs).
        app.store.request(np.asarray(app.store.command.q), "runner")
        others = [threading.Thread(target=panel.on_state, args=(app.store.display,)),
                  threading.Thread(target=user, args=(z_in, op, typed[2]))]
        for t in others:
            t.start()
        for t in others:
            t.join(1.0)  # done before x goes on (or waiting for x's callback to finish)
        go.set()
        for t in (x_thread, *others):
            t.join(30)
            assert not t.is_alive()
        assert submitted == []  # typed, not applied
        np.testing.assert_allclose([float(h.value) for h in panel.inputs], typed)
        user(panel.go, op)
        assert len(submitted) == 1
        np.testing.assert_allclose(submitted[-1], typed)
        np.testing.assert_allclose([float(h.value) for h in panel.inputs], typed)
    finally:
        app.stop()
