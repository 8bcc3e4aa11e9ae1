"""The extensible arm jogs at a speed a class can follow, set by the operator (issue 31, item 6).

Holding + on a Δ jog for 2 s used to sweep the tip ~255 mm (the jog's sweep rate under the
250 mm/s cap). Now the console core starts the extensible arm's jog speed at 20 mm/s for the
fastest arm point, and the Jog panel's "Jog speed (mm/s)" field changes it within limits (a bad
value is said and changes nothing). Measured here on the kinematics: the tip of every commanded
posture by forward kinematics (``core.kinematics.delta.tip_position``), its finite differences
over a simulated clock (hold-to-run steps at 50 Hz, the button's renewals at 20 Hz as a browser
sends them, the lease's heartbeats every 0.1 s).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
import viser
from fakes import FakeClient, FakeClock, console_app, user

from console.core.access import AccessControl
from console.panels.common.jog import HOLD_HZ, JogPanel
from core.kinematics import delta as dk
from core.robots import load

EXT = load("extensible")
DT = 0.02  # s, hold-to-run's step at 50 Hz
TOL = 1e-6  # relative, on a speed


@pytest.fixture
def jog_console(server: Any):
    clock = FakeClock()
    app = console_app(EXT, server, panels=(JogPanel,), access=AccessControl("tok", clock=clock),
                      clock=clock)
    try:
        op = FakeClient(7)
        app.access.take(op.client_id, "tok", name="Alice")
        yield app, app.panel(JogPanel), op, clock
    finally:
        app.stop()


def tip_mm(app: Any) -> np.ndarray:
    return dk.tip_position(EXT, np.asarray(app.store.command.q)) * 1e3


def hold_plus(app: Any, jog: JogPanel, op: FakeClient, clock: FakeClock, key: str,
              seconds: float) -> list[np.ndarray]:
    """Hold row ``key``'s + for ``seconds`` (renewed at HOLD_HZ, as the browser does), let go,
    then 0.5 s more; the tip (mm) after every step."""
    row = next(r for r in jog.rows if r.coord.key == key)
    renew = row.plus._impl.hold_cbs_from_freq[HOLD_HZ]
    event = viser.GuiEvent(client=op, client_id=op.client_id, target=row.plus)  # type: ignore
    tips = [tip_mm(app)]
    steps = int(round(seconds / DT))
    for k in range(steps):
        if k % int(round(1.0 / HOLD_HZ / DT)) == 0 or k == 0:
            for cb in renew:
                cb(event)
        clock.t += DT
        app.core.hold.tick()
        tips.append(tip_mm(app))
    user(row.plus, op)  # mouse-up: the click ends the hold
    for _ in range(int(round(0.5 / DT))):
        clock.t += DT
        app.core.hold.tick()
        tips.append(tip_mm(app))
    return tips


def travelled(tips: list[np.ndarray]) -> tuple[float, float]:
    """(largest speed between two steps in mm/s, distance from first to last tip in mm)."""
    steps = np.linalg.norm(np.diff(np.array(tips), axis=0), axis=1)
    return float(steps.max() / DT), float(np.linalg.norm(tips[-1] - tips[0]))


def test_a_held_extension_jog_moves_the_tip_at_20_mm_per_s_and_the_field_changes_it(
        jog_console) -> None:
    app, jog, op, clock = jog_console
    assert jog.speed.value == pytest.approx(20.0)  # the field shows the core's speed
    fastest, moved = travelled(hold_plus(app, jog, op, clock, "dL1", 2.0))
    assert fastest <= 20.0 * (1 + TOL)
    assert 0.9 * 2.0 * 20.0 <= moved <= 2.0 * 20.0 + 20.0 * DT  # (+ one step of tolerance)
    assert not app.core.hold.active

    user(jog.speed, op, 50.0)  # the operator asks for 50 mm/s
    assert app.core.hold.jog_speed == pytest.approx(0.050)
    fastest, moved = travelled(hold_plus(app, jog, op, clock, "dL1", 2.0))
    assert fastest <= 50.0 * (1 + TOL)
    assert 0.9 * 2.0 * 50.0 <= moved <= 2.0 * 50.0 + 50.0 * DT


def test_a_held_bend_jog_keeps_every_arm_point_within_the_jog_speed(jog_console) -> None:
    """A bend of segment 1 swings the tip furthest: the tip too stays within 20 mm/s."""
    app, jog, op, clock = jog_console
    fastest, moved = travelled(hold_plus(app, jog, op, clock, "dx1", 2.0))
    assert fastest <= 20.0 * (1 + TOL) and 0 < moved <= 2.0 * 20.0 + 20.0 * DT


def test_a_jog_slider_moves_at_the_jog_speed_too(jog_console) -> None:
    app, jog, op, clock = jog_console
    row = next(r for r in jog.rows if r.coord.key == "dL2")
    start = tip_mm(app)
    user(row.slider, op, float(row.slider.value) + 60.0)  # 60 mm further out, typed
    tips = [start]
    for k in range(int(round(5.0 / DT))):
        if k % 5 == 0:
            app.access.heartbeat(op)  # the lease probe's answers (a set-point needs them)
        clock.t += DT
        app.core.hold.tick()
        tips.append(tip_mm(app))
    fastest, moved = travelled(tips)
    assert fastest <= 20.0 * (1 + TOL)
    assert moved == pytest.approx(60.0, abs=1e-6)  # arrived, 3 s at 20 mm/s


@pytest.mark.parametrize("asked", [0.0, 500.0, -5.0])
def test_a_jog_speed_outside_the_limits_is_said_and_changes_nothing(jog_console,
                                                                   asked: float) -> None:
    app, jog, op, _ = jog_console
    seq = app.store.command.seq
    user(jog.speed, op, asked)
    assert app.core.hold.jog_speed == pytest.approx(0.020)
    assert jog.speed.value == pytest.approx(20.0)  # the field back at the speed in force
    assert "Jog speed not changed" in jog.note.content
    assert "between 1 and 100 mm/s" in jog.note.content  # limits.tip_speed = 0.10 m/s
    assert app.store.command.seq == seq  # nothing moved
