"""The extensible arm's Tip target and Paths panels answer every action (issue #19.5): a plan
that never comes back is reported after a timeout (the requested path drawn meanwhile), the
"Hardware:" line is the link supervisor's health (as the Hardware panel and the header show
it), the header's Phase says what the runner does, and an unreachable target names the
closest reachable tip; no "-0" anywhere."""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import re

import numpy as np
from fakes import FakeRunner
from ws_client import wait_for

from core.kinematics import delta as dk
from core.kinematics.delta_ik import solve_tip_ik
from core.robots import load

EXT = load("extensible")


@dataclasses.dataclass
class FakeHealth:
    """The LinkHealth fields the texts read."""

    state: str = "active"
    port: str = "/dev/pts/9"
    fault: str | None = None
    armed: bool = True


class FakeControls:
    def __init__(self, health: FakeHealth | None) -> None:
        self.h = health

    def health(self) -> FakeHealth | None:
        return self.h


@dataclasses.dataclass
class FakeHardware:
    kind: str


class NeverAnswers:
    """A planner pool whose plans never come back (a stuck worker)."""

    def __init__(self) -> None:
        self.futures: list[cf.Future] = []

    def submit(self, *args, **kwargs) -> cf.Future:
        self.futures.append(cf.Future())
        return self.futures[-1]

    def shutdown(self, wait: bool = True, cancel_futures: bool = False) -> None:
        pass


def status_of(html: str) -> str:
    return re.search(r'data-state="(\w+)"', html).group(1)


def test_a_plan_that_never_returns_is_drawn_as_requested_then_reported(server, monkeypatch):
    from fakes import console_app

    from console.panels.extensible import paths

    monkeypatch.setattr(paths, "PLAN_TIMEOUT_S", 1.0)
    app = console_app(EXT, server, panels=(), extensible_runner=FakeRunner(),
                      hardware=FakeHardware("mock"))
    panel = app.add_panel(paths.PathsPanel)
    stuck = NeverAnswers()
    monkeypatch.setattr(panel, "_plan_pool", lambda: stuck)
    panel._request_plan(execute=False)
    # At once: the requested tip path (centred on the tip, build_path) is drawn and said so.
    assert status_of(panel.status.content) == "planning"
    assert 'data-drawn="requested"' in panel.status.content
    tip = dk.tip_position(EXT, np.asarray(app.store.command.q))
    want = paths.build_path("linear", tip, 0.08, "xy")
    np.testing.assert_allclose(panel.drawing.waypoints.points, want, atol=1e-6)
    assert panel.drawing.trace.visible
    # The worker never answers: after the timeout the panel says so (the 2 Hz status loop).
    assert wait_for(lambda: status_of(panel.status.content) == "error")
    assert "no answer within 1 s" in panel.status.content
    # A late answer of the abandoned plan changes nothing.
    stuck.futures[0].set_exception(RuntimeError("late"))
    assert "no answer within 1 s" in panel.status.content
    # A failing plan says why at once.
    panel._request_plan(execute=False)
    stuck.futures[-1].set_exception(ValueError("speed 9 m/s exceeds the tip speed limit"))
    assert status_of(panel.status.content) == "error"
    assert "exceeds the tip speed limit" in panel.status.content
    app.stop()


def test_hardware_line_is_the_link_supervisors_health_and_phase_follows_stop(server):
    from fakes import console_app

    from console.panels.extensible.status import link_summary
    from console.panels.common.hardware import header_link
    from console.panels.extensible.paths import PathsPanel

    controls = FakeControls(FakeHealth(fault="link lost: no valid STATE for 48 ms"))
    app = console_app(EXT, server, panels=(), extensible_runner=FakeRunner(),
                      bridge_controls=controls, hardware=FakeHardware("emulator"),
                      mirror_commands=False)
    panel = app.add_panel(PathsPanel)
    said = header_link("emulator", controls.h)[0]  # the header's Link field
    assert link_summary(app) == said == "emulator · link lost: no valid STATE for 48 ms"
    assert wait_for(lambda: said in panel.hardware.content)
    assert "connects on the first Execute" not in panel.hardware.content
    controls.h = FakeHealth()
    assert wait_for(lambda: "emulator · active · ARMED" in panel.hardware.content)
    assert wait_for(lambda: ">idle<" in app.header.status.content.replace("</span>", "<"))
    app.stop_motion("client 0's tab went silent for 2 s")  # stops motion; was idle: still idle
    assert ">idle<" in app.header.status.content.replace("</span>", "<")
    app.stop_motion("STOP pressed by client 0")  # the panel shows the core's state (2 Hz)
    assert wait_for(lambda: "holding after STOP" in app.header.status.content)
    app.stop()

    mock = console_app(EXT, server, panels=(), extensible_runner=FakeRunner(),
                       hardware=FakeHardware("mock"))
    assert link_summary(mock).startswith("mock · not connected")
    assert "first Execute" in link_summary(mock)
    mock.stop()


def test_unreachable_target_names_the_closest_reachable_tip_without_negative_zero(server):
    from fakes import console_app

    from console.panels.extensible.target import TargetPanel

    app = console_app(EXT, server, panels=(), extensible_runner=FakeRunner(),
                      hardware=FakeHardware("mock"))
    panel = app.add_panel(TargetPanel)
    far = np.array([-1e-7, 0.0, 0.9])  # beyond the 820 mm arm, x a hair below 0
    result = solve_tip_ik(EXT, far)
    assert not result.reachable
    text = panel._status_html(result, None, None, far)
    assert 'data-state="unreachable"' in text and "-0" not in text.replace("−", "")
    assert "(0.0, 0.0, 900.0) mm is beyond the arm's reach" in text
    tip = ", ".join(f"{v * 1e3:.1f}".replace("-0.0", "0.0") for v in result.tip)
    assert f"closest reachable tip, ({tip}) mm" in text
    assert f"{result.error * 1e3:.1f} mm</b> from the target" in text
    app.stop()


def test_a_typed_field_is_not_overwritten_by_the_echo_of_the_field_typed_before_it(server):
    """Typing x then y: viser stores y before y's callback runs; the panel's echo of an answer
    (target with the old y) came in between in a CI run and wrote the old y back, so y's
    callback solved for the old y. The echo now leaves a field typed since alone (and writes
    no field while a typed target is pending); Go solves for every field as typed."""
    from fakes import FakeClient, console_app, user

    from console.core.access import AccessControl
    from console.panels.extensible.target import TargetPanel

    app = console_app(EXT, server, panels=(), extensible_runner=FakeRunner(),
                      hardware=FakeHardware("mock"), access=AccessControl("tok"))
    try:
        panel = app.add_panel(TargetPanel)
        solves: list[np.ndarray] = []
        panel.worker.submit = lambda target, *a: solves.append(np.array(target))
        op = FakeClient(7)
        app.access.take(op.client_id, "tok", name="Alice")
        x_in, y_in, z_in = panel.inputs
        y0, z0 = float(y_in.value), float(z_in.value)
        x0 = float(x_in.value)
        user(x_in, op, 120.0)                         # x typed: pending (120, y0, z0)
        assert solves == []                           # typing alone solves and moves nothing
        user(panel.go, op)                            # Go: solved for (120, y0, z0)
        np.testing.assert_allclose(solves[-1] * 1e3, (120.0, y0, z0))
        y_in._impl.value = y0 - 60.0                  # y typed: stored, its callback queued
        panel._publish(solves[-1], None, None, "x's answer")
        panel._show()                                 # the echo of x's answer
        assert float(y_in.value) == y0 - 60.0
        user(y_in, op)                                # y's callback: pending, not solved
        assert len(solves) == 1
        panel._publish(np.array([x0, y0, z0]) / 1e3, None, None, "a tip reset")
        panel._show()                                 # an echo while pending: fields kept
        assert [float(h.value) for h in panel.inputs] == [120.0, y0 - 60.0, z0]
        user(panel.go, op)
        np.testing.assert_allclose(solves[-1] * 1e3, (120.0, y0 - 60.0, z0))
        # Fields the panel has shown again follow its answers: back on the tip, all three.
        user(panel.to_tip, op)
        tip = dk.tip_position(EXT, np.asarray(app.store.command.q)) * 1e3
        np.testing.assert_allclose([float(h.value) for h in panel.inputs], tip, atol=0.05)
    finally:
        app.stop()
