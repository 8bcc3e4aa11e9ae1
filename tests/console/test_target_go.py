"""Typed tip targets are applied together, by Go (issue 31, item 6).

Typing x, y, z into the extensible arm's Tip target used to move the arm once per field, through
two targets nobody asked for. Now typing only shows a pending target (a dimmed ball, a status
that says it is not applied) and moves nothing; Go moves once, to exactly the typed target. The
expectations are the test's own: the commands the arm's loop receives (a runner that counts its
set-points), the moves hold-to-run is asked for, and the tip of the posture the arm ends at by
forward kinematics (``core.kinematics.delta.tip_position``), compared with the typed numbers.
Time is a simulated clock (hold-to-run steps and the lease's heartbeats); the IK runs in this
process (a pool that answers at once) on the panel's own worker thread, waited for by what it
does, never by how long it takes.
"""

from __future__ import annotations

import dataclasses
import re
from typing import Any

import numpy as np
import pytest
from fakes import FakeClient, FakeClock, FakeRunner, SyncPool, console_app, user
from ws_client import wait_for

from console.core.access import AccessControl
from core.kinematics import delta as dk
from core.robots import load

EXT = load("extensible")
TYPED_MM = (120.0, -60.0, 350.0)  # reachable: IK solves it exactly


class CountingRunner(FakeRunner):
    """A started runner that keeps every set-point the console core forwards to it."""

    started = True

    def __init__(self) -> None:
        super().__init__()
        self.setpoints: list[np.ndarray] = []

    def setpoint(self, seq: int, delta: Any) -> None:
        self.setpoints.append(np.array(delta, dtype=float))


@dataclasses.dataclass
class FakeHardware:
    kind: str


def state_of(html: str, key: str = "state") -> str:
    found = re.search(rf'data-{key}="([^"]*)"', html)
    assert found, (key, html)
    return found.group(1)


@pytest.fixture
def target_console(server: Any, monkeypatch: pytest.MonkeyPatch):
    from console.panels.extensible.target import TargetPanel

    clock = FakeClock()
    runner = CountingRunner()
    app = console_app(EXT, server, panels=(), extensible_runner=runner,
                      hardware=FakeHardware("mock"), access=AccessControl("tok", clock=clock),
                      clock=clock)
    try:
        panel = app.add_panel(TargetPanel)
        monkeypatch.setattr(panel, "_ik_pool", lambda: SyncPool())
        moves: list[np.ndarray] = []
        hold = app.core.hold
        real_move_to = hold.move_to

        def counted(client_id: int, target: Any, **kw: Any) -> bool:
            moves.append(np.array(target, dtype=float))
            return real_move_to(client_id, target, **kw)

        monkeypatch.setattr(hold, "move_to", counted)
        op = FakeClient(7)
        app.access.take(op.client_id, "tok", name="Alice")
        yield app, panel, runner, moves, op, clock
    finally:
        app.stop()


def run(app: Any, op: FakeClient, clock: FakeClock, seconds: float) -> None:
    """``seconds`` of simulated time: hold-to-run steps at 50 Hz, the operator's tab answers
    every 0.1 s, and the core forwards each new command to the runner."""
    for k in range(int(round(seconds / 0.02))):
        if k % 5 == 0:
            app.access.heartbeat(op)
        clock.t += 0.02
        app.core.hold.tick()
        app.core.tick()


def test_typing_moves_nothing_and_go_makes_one_move_to_exactly_the_typed_target(
        target_console) -> None:
    app, panel, runner, moves, op, clock = target_console
    start_q = np.array(app.store.command.q)
    start_seq = app.store.command.seq
    for handle, value in zip(panel.inputs, TYPED_MM):
        user(handle, op, value)
        run(app, op, clock, 0.5)
    # Typed, not applied: nothing asked of hold-to-run, nothing commanded, nothing sent.
    assert moves == [] and app.core.hold.target() is None
    assert app.store.command.seq == start_seq and runner.setpoints == []
    np.testing.assert_array_equal(app.store.command.q, start_q)
    status = panel.status.content
    assert state_of(status) == "pending" and state_of(status, "pending-mm") == "120.0,-60.0,350.0"
    assert "not applied" in status and "Go" in status
    assert panel.pending_ball.visible
    np.testing.assert_allclose(panel.pending_ball.position, np.array(TYPED_MM) / 1e3)

    user(panel.go, op)
    wait_for(lambda: len(moves) >= 1 and state_of(panel.status.content) != "solving",
             timeout=60.0, what=lambda: f"the move after Go ({panel.status.content})")
    assert not panel.pending_ball.visible
    assert state_of(panel.status.content) == "reachable", panel.status.content
    run(app, op, clock, 30.0)  # far longer than the move takes at the capped speed
    assert len(moves) == 1  # one move, to the posture whose tip is the typed target
    goal_tip_mm = dk.tip_position(EXT, moves[0]) * 1e3
    np.testing.assert_allclose(goal_tip_mm, TYPED_MM, atol=0.01)
    # The loop received only postures on the way from the start to that one, and ended there.
    assert runner.setpoints
    path = moves[0] - start_q
    for q in runner.setpoints:
        s = float(np.sum((q - start_q) * path) / np.sum(path * path))
        assert -1e-9 <= s <= 1 + 1e-9
        np.testing.assert_allclose(q, start_q + s * path, atol=1e-9)
    np.testing.assert_allclose(dk.tip_position(EXT, runner.setpoints[-1]) * 1e3, TYPED_MM,
                               atol=0.01)
    np.testing.assert_allclose(dk.tip_position(EXT, np.asarray(app.store.command.q)) * 1e3,
                               TYPED_MM, atol=0.01)


def test_a_bad_field_on_go_is_said_and_moves_nothing(target_console) -> None:
    app, panel, runner, moves, op, clock = target_console
    x_in, y_in, z_in = panel.inputs
    shown = [float(h.value) for h in panel.inputs]
    z_in._impl.value = float("nan")  # (a browser cannot send one; a broken client could)
    user(panel.go, op)
    run(app, op, clock, 1.0)
    assert moves == [] and runner.setpoints == [] and app.core.hold.target() is None
    assert state_of(panel.status.content) == "error"
    assert "three finite numbers" in panel.status.content and "Not moved" in panel.status.content
    assert [float(h.value) for h in panel.inputs] == shown  # the fields went back


def test_target_to_tip_discards_a_pending_target(target_console) -> None:
    app, panel, runner, moves, op, clock = target_console
    user(panel.inputs[0], op, 150.0)
    assert state_of(panel.status.content) == "pending"
    user(panel.to_tip, op)
    tip_mm = dk.tip_position(EXT, np.asarray(app.store.command.q)) * 1e3
    assert state_of(panel.status.content) == "idle" and not panel.pending_ball.visible
    np.testing.assert_allclose([float(h.value) for h in panel.inputs], tip_mm, atol=0.05)
    user(panel.go, op)  # Go now: the fields hold the tip, so the arm stays where it is
    wait_for(lambda: state_of(panel.status.content) not in ("solving", "idle"), timeout=60.0,
             what=lambda: f"the answer to Go ({panel.status.content})")
    run(app, op, clock, 2.0)
    np.testing.assert_allclose(dk.tip_position(EXT, np.asarray(app.store.command.q)) * 1e3,
                               tip_mm, atol=0.01)
