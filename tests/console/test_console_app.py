"""ConsoleApp without a browser: geometry matches the kinematics, updates happen in place,
rendering coalesces to the newest state, panels plug in, hardware feedback drives the view."""

from __future__ import annotations

import re
import time

import numpy as np
import pytest

from console.app import ConsoleApp
from console.scene.arm_view_factory import make_arm_view
from console.scene.extensible_arm_view import ExtensibleArmView
from console.scene.soft_arm_view import SoftArmView
from console.panels.common.base import Panel
from console.panels.common.jog import JogPanel
from console.panels.common.readout import ReadoutPanel
from console.core.state import ArmState
from core.kinematics import delta as dk
from core.kinematics import planar as pk
from core.robots import load

SOFT = load("soft-arm")
EXT = load("extensible")



def wait_until(predicate, timeout: float = 3.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError("condition not reached")
        time.sleep(0.01)


def ring_centres(view: SoftArmView, vertices: np.ndarray) -> np.ndarray:
    k, m = view.body_topology.sides, view.body_topology.n_rings
    return vertices[: m * k].reshape(m, k, 3).astype(float).mean(axis=1)


def test_planar_tube_follows_the_backbone_and_gripper_and_palm_sit_on_the_tip(server) -> None:
    app = ConsoleApp(SOFT, server)
    view = app.view
    assert isinstance(view, SoftArmView)
    kappa = np.array([5.0, -3.0, 16.7, 0.0, -10.0, 2.0])
    g = view.geometry(kappa)
    backbone = pk.sample_backbone(kappa, SOFT.lengths, view.samples_per_segment, SOFT.base_pose)
    centres = ring_centres(view, g["body"])
    np.testing.assert_allclose(centres[:, :2], backbone[:, :2], atol=1e-6)
    np.testing.assert_allclose(centres[:, 2], SOFT.half_width, atol=1e-6)  # resting on table
    tip = pk.forward_kinematics(kappa, SOFT.lengths, SOFT.base_pose)[-1]
    np.testing.assert_allclose(centres[-1, :2], tip[:2], atol=1e-6)
    # Gripper: straight, gripper.length long, along the tip heading.
    gripper = g["gripper"][: 2 * view.sides].reshape(2, view.sides, 3).astype(float).mean(1)
    heading = np.array([np.cos(tip[2]), np.sin(tip[2])])
    np.testing.assert_allclose(gripper[1, :2] - gripper[0, :2], SOFT.gripper.length * heading,
                               atol=1e-6)
    a, n = SOFT.gripper.w_off
    left = np.array([-heading[1], heading[0]])
    np.testing.assert_allclose(g["palm"][:2], tip[:2] + a * heading + n * left, atol=1e-12)
    # One boundary ring per segment end, centred on it.
    ends = pk.forward_kinematics(kappa, SOFT.lengths, SOFT.base_pose)[1:]
    rings = g["rings"].astype(float)[: view.ring_topology.n_vertices]
    per = view.ring_topology.vertices_per_tube
    band = rings.reshape(SOFT.n_segments, per, 3)[:, : 2 * view.sides].mean(axis=1)
    np.testing.assert_allclose(band[:, :2], ends[:, :2], atol=1e-6)


def polyline_length(points: np.ndarray) -> np.ndarray:
    return np.linalg.norm(np.diff(points, axis=-2), axis=-1).sum(axis=-1)


def test_extensible_racks_are_drawn_with_their_commanded_lengths(server) -> None:
    app = ConsoleApp(EXT, server)
    view = app.view
    assert isinstance(view, ExtensibleArmView)
    q = np.array([[0.03, -0.02, 0.2], [-0.01, 0.025, 0.12]])  # about 1.2 and 0.9 rad of bend
    g = view.geometry(q)
    beta = -EXT.phi + 2 * np.pi * np.arange(3) / 3
    expected = EXT.L0 + q[:, 2:3] - q[:, 0:1] * np.cos(beta) - q[:, 1:2] * np.sin(beta)
    drawn = np.stack([polyline_length(c) for c in g["rack_centres"]], axis=-1)  # (n, 3)
    # A 32-chord polyline of an arc is shorter by at most (angle/32)^2/24 relative.
    np.testing.assert_allclose(drawn, expected, rtol=1e-4)
    frames = dk.forward_kinematics(q, EXT.L0, EXT.d)
    np.testing.assert_allclose(g["tip_position"], frames[-1, :3, 3], atol=1e-12)
    np.testing.assert_allclose(g["tip_position"], dk.tip_position(EXT, q), atol=1e-12)


def test_render_updates_the_same_handles_in_place(server) -> None:
    app = ConsoleApp(EXT, server)
    app.view = make_arm_view(server.scene, app.model, method="vertices", dead_band=None)
    view = app.view
    handles = (view.backbone, *view.racks, view.platforms, view.tip)
    before = [h.vertices.copy() for h in handles[:-1]]
    with app:
        q = np.array([[0.02, 0.0, 0.15], [0.0, 0.0, 0.1]])
        state = app.store.request(q, "test")
        wait_until(lambda: app.frames_drawn >= 1 and app.last_drawn_seq == state.seq)
    assert (view.backbone, *view.racks, view.platforms, view.tip) == handles
    assert all(not np.array_equal(h.vertices, b) for h, b in zip(handles[:-1], before))
    np.testing.assert_allclose(view.backbone.vertices, view.geometry(q)["backbone"], atol=1e-6)
    np.testing.assert_allclose(view.tip.position, dk.tip_position(EXT, q), atol=1e-6)


def test_a_burst_of_requests_draws_the_newest_state_at_a_bounded_rate(server) -> None:
    app = ConsoleApp(SOFT, server, render_hz=20.0)
    app.view = make_arm_view(server.scene, app.model, method="vertices", dead_band=None)
    with app:
        start = time.perf_counter()
        for k in np.linspace(0.0, 10.0, 200):  # a request every ~2 ms for ~0.4 s
            last = app.store.request(np.full(6, k), "burst")
            time.sleep(0.002)
        wait_until(lambda: app.last_drawn_seq == last.seq)
        elapsed = time.perf_counter() - start
    assert app.frames_drawn <= elapsed * 20.0 + 2  # skipped, never caught up
    assert app.frames_drawn < 200
    tip = pk.forward_kinematics(np.full(6, 10.0), SOFT.lengths, SOFT.base_pose)[-1]
    centres = ring_centres(app.view, app.view.body.vertices)
    np.testing.assert_allclose(centres[-1, :2], tip[:2], atol=1e-6)


def readout_cell(html: str, testid: str) -> float:
    match = re.search(rf'data-testid="{testid}"[^>]*>(?:<[^>]+>)*([-+0-9.]+)', html)
    assert match, f"{testid} not in readout"
    return float(match.group(1))


def test_readout_shows_tip_pose_and_flags_racks_near_limits(server) -> None:
    app = ConsoleApp(EXT, server)
    q = np.array([[0.0, 0.0, 0.357], [0.0, 0.0, 0.1]])  # segment 1 racks 3 mm below rack_max
    with app:
        state = app.store.request(q, "test")
        wait_until(lambda: app.last_drawn_seq == state.seq)
    html = app.panel(ReadoutPanel).html.content
    tip = dk.tip_position(EXT, q)
    assert readout_cell(html, "tip-2") == pytest.approx(tip[2] * 1e3, abs=0.051)
    assert readout_cell(html, "rack-1-2") == pytest.approx(407.0, abs=0.051)
    assert html.count('data-near-limit="true"') == 3
    assert readout_cell(html, "rack-2-1") == pytest.approx(150.0, abs=0.051)


def test_requests_from_other_sources_move_the_jog_sliders(server) -> None:
    app = ConsoleApp(SOFT, server)
    with app:
        state = app.store.request([1.0, 2.0, 3.0, -4.0, 0.0, 30.0], "planner")
        wait_until(lambda: app.last_drawn_seq == state.seq)
    jog = app.panel(JogPanel)
    values = [jog.sliders[f"kappa{i}"].value for i in range(1, 7)]
    assert values == pytest.approx([1.0, 2.0, 3.0, -4.0, 0.0, SOFT.kappa_max])
    assert state.notes and "κ₆" in state.notes[0]
    assert "κ₆ clamped" in jog.note.content


def test_bad_request_raises_and_moves_nothing(server) -> None:
    app = ConsoleApp(SOFT, server)
    before = app.store.command
    with pytest.raises(ValueError, match="shape"):
        app.store.request(np.zeros(3), "test")
    with pytest.raises(ValueError, match="finite"):
        app.store.request([0, 0, 0, np.inf, 0, 0], "test")
    assert app.store.command is before and app.store.display is before


def test_with_hardware_the_view_shows_reported_not_commanded_state(server) -> None:
    app = ConsoleApp(SOFT, server, mirror_commands=False)
    app.view = make_arm_view(server.scene, app.model, method="vertices", dead_band=None)
    commanded = app.store.request(np.full(6, 5.0), "jog")
    assert app.store.display.seq == 0  # nothing measured yet
    assert app.store.wait_command(0, timeout=1.0) is commanded  # what a bridge would read
    with app:
        measured = app.store.report(np.full(6, 4.0), "hardware")
        wait_until(lambda: app.last_drawn_seq == measured.seq)
    tip = pk.forward_kinematics(np.full(6, 4.0), SOFT.lengths, SOFT.base_pose)[-1]
    np.testing.assert_allclose(ring_centres(app.view, app.view.body.vertices)[-1, :2], tip[:2],
                               atol=1e-6)


class PlanarOnlyPanel(Panel):
    title = "Planar only"
    order = 50.0
    kinds = ("planar",)

    def build(self) -> None:
        self.seen: list[ArmState] = []
        self.label = self.gui.add_markdown("waiting")

    def on_state(self, state: ArmState) -> None:
        self.seen.append(state)
        self.label.content = f"seq {state.seq}"


class BrokenPanel(Panel):
    title = "Broken"

    def build(self) -> None:
        pass

    def on_state(self, state: ArmState) -> None:
        raise RuntimeError("boom")


def test_panels_plug_in_by_class_and_a_broken_panel_does_not_stop_drawing(server) -> None:
    app = ConsoleApp(SOFT, server)
    extra = app.add_panel(PlanarOnlyPanel)
    app.add_panel(BrokenPanel)
    assert app.panel(PlanarOnlyPanel) is extra
    assert [type(p) for p in app.panels] == [JogPanel, ReadoutPanel, PlanarOnlyPanel, BrokenPanel]
    with app:
        state = app.store.request(np.full(6, 1.0), "test")
        wait_until(lambda: app.last_drawn_seq == state.seq)
    assert extra.seen[-1] is state and extra.label.content == f"seq {state.seq}"
    assert ConsoleApp(EXT, server, panels=[PlanarOnlyPanel]).panels == ()
    with pytest.raises(KeyError):
        app.panel(type("Missing", (Panel,), {}))


def test_services_come_in_typed_and_nothing_is_made_behind_the_callers_back(server) -> None:
    from console.panels.soft_arm.control import ControlPanel
    from console.panels.extensible.paths import PathsPanel
    from fakes import console_app

    app = console_app(SOFT, server, panels=(), demo=True)
    demo = app.services.demo
    assert demo is not None and app.services.soft_control is None
    demo.start()
    deadline = time.monotonic() + 5.0
    while app.store.command.source != "demo" and time.monotonic() < deadline:
        time.sleep(0.02)
    assert demo.running and app.store.command.source == "demo"
    app.stop_motion("test STOP")  # the demo's stop hook was registered by the app
    assert not demo.running
    with pytest.raises(ValueError, match="control process"):
        app.add_panel(ControlPanel)  # no process started for it: a clear error instead
    ext = console_app(EXT, server, panels=())
    with pytest.raises(ValueError, match="runner"):
        ext.add_panel(PathsPanel).runner  # type: ignore[union-attr]
    with pytest.raises(ValueError, match="store= .* or initial="):
        ConsoleApp(SOFT, server, store=app.store, initial=np.zeros(6))
