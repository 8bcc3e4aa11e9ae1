"""The shipped extensible arm's console flows, without a browser: typed tip target, path run, and
the measured tip on the device emulator (a typed target is x, y, z and Go).

``serve.build`` (what ``serve.py --robot extensible`` runs, in this process) composes every panel
of the arm. A raw websocket client (a real tab to the lease) types the tip target; the buttons
(Arm device, Connect, Preview, Execute) are clicked by a FakeClient with that tab's id, as viser
calls back for a click. Expectations are the test's own: the IK (``solve_tip_ik``) says a target
is reachable, forward kinematics of the Δ jog sliders' values gives their tip, ``build_path``
gives the path's end, the robot file gives the rack limits and the tip speed. Was
tests/browser/test_browser_extensible.py (three Chromium tests on serve.py subprocesses).

The suite runs these beside another test on two busy cores: every wait has a deadline far above
what it takes, links are patient where a device runs, and the one time compared (the measured
tip takes no less than the tip speed allows) is a lower bound that load only makes easier.
"""

from __future__ import annotations

import re
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest
from robot_files import robot_copy

from console.core.model import ExtensibleModel
from core.kinematics import delta as dk
from core.kinematics.delta_ik import solve_tip_ik
from core.planning.paths import build_path
from core.robots import load
from fakes import FakeClient, user
from tests.ws_client import RawClient, wait_for

ROBOT = load("extensible")


@pytest.fixture
def served(served_console: Callable[..., Any]) -> Callable[..., Any]:
    """``served(robot, hardware, *more_args)``: the console serve.py builds, started
    (conftest ``served_console``)."""
    return lambda robot, hardware, *more: served_console(robot, hardware, *more, start=True)


@pytest.fixture
def tab(served: Callable[..., Any]) -> Iterator[Callable[..., tuple[Any, RawClient]]]:
    """``tab(robot, hardware, *more_args)``: the served console and a raw websocket tab holding
    its lease."""
    tabs: list[RawClient] = []

    def open_tab(robot: str, hardware: str, *more_args: str) -> tuple[Any, RawClient]:
        app = served(robot, hardware, *more_args)
        client = RawClient(app.server)
        tabs.append(client)
        app.access.take(client.client_id, None, name="tester")
        return app, client

    yield open_tab
    for client in tabs:
        client.close()


def panels(app: Any) -> tuple[Any, Any, Any, Any, Any]:
    from console.panels.common.hardware import HardwarePanel
    from console.panels.common.jog import JogPanel
    from console.panels.common.readout import ReadoutPanel
    from console.panels.extensible.paths import PathsPanel
    from console.panels.extensible.target import TargetPanel

    return (app.panel(TargetPanel), app.panel(ReadoutPanel), app.panel(JogPanel),
            app.panel(PathsPanel), app.panel(HardwarePanel))


def readout_tip(readout: Any) -> np.ndarray:
    """The tip readout's x, y, z (mm) as the page shows them."""
    cells = dict(re.findall(r'data-testid="tip-(\d)"[^>]*>(?:<code>)?([^<]*)<',
                            readout.html.content))
    return np.array([float(cells[str(k)].replace("⚠", "")) for k in range(3)])


def rack_cells(readout: Any) -> list[float]:
    """The rack readout's lengths (mm) as the page shows them."""
    cells = re.findall(r'data-testid="rack-\d+-\d+" data-near-limit="\w+">'
                       r'<span[^>]*>([^<]*)</span>', readout.html.content)
    return [float(c.replace("⚠", "")) for c in cells]


def jog_tip(jog: Any) -> np.ndarray:
    """The tip (mm) of the posture the Δ jog sliders hold (their values are mm)."""
    q = np.zeros((ROBOT.n_segments, 3))
    for coord in jog.app.model.coordinates:
        q[coord.index] = float(jog.sliders[coord.key].value) / 1e3
    return dk.tip_position(ROBOT, q) * 1e3


def attr(html: str, name: str) -> str:
    found = re.search(rf'{name}="([^"]*)"', html)
    assert found, (name, html)
    return found.group(1)


def type_target(client: RawClient, target: Any, xyz_mm: np.ndarray) -> None:
    """Type x, y, z and press Go (typing alone moves nothing)."""
    for handle, value in zip(target.inputs, xyz_mm):
        assert client.update(handle._impl.uuid, value=float(value))
    assert client.update(target.go._impl.uuid, value=True)


def test_typed_target_moves_the_tip_and_the_jog_sliders(tab: Callable[..., Any]) -> None:
    app, client = tab("extensible", "mock")
    target, readout, jog, _, _ = panels(app)
    aim = np.array([120.0, -60.0, 350.0])  # mm
    ik = solve_tip_ik(ROBOT, aim / 1e3)
    assert ik.reachable and np.linalg.norm(dk.tip_position(ROBOT, ik.delta) - aim / 1e3) < 1e-3
    type_target(client, target, aim)
    wait_for(lambda: np.abs(readout_tip(readout) - aim).max() <= 1.0, timeout=30.0,
             what="the tip readout at the target")
    assert attr(target.status.content, "data-state") == "reachable", target.status.content
    # The jog sliders mirror the posture the IK chose (the panel rounds them to 1e-6 mm).
    wait_for(lambda: np.linalg.norm(jog_tip(jog) - aim) <= 1.0, what="the jog sliders in sync")

    far = np.array([900.0, -60.0, 350.0])  # beyond the 820 mm arm
    assert not solve_tip_ik(ROBOT, far / 1e3).reachable
    type_target(client, target, far)
    wait_for(lambda: attr(target.status.content, "data-state") == "unreachable", timeout=30.0,
             what="the unreachable status")
    said = float(attr(target.status.content, "data-error-mm"))
    wait_for(lambda: abs(np.linalg.norm(readout_tip(readout) - far) - said) <= 0.2,
             what="the readout at the closest feasible tip")
    assert said > 1.0 and f"{said:.1f} mm" in target.status.content
    racks = rack_cells(readout)
    assert len(racks) == 3 * ROBOT.n_segments
    assert min(racks) >= ROBOT.rack_min * 1e3 - 0.05 and max(racks) <= ROBOT.rack_max * 1e3 + 0.05
    assert app.access.is_operator(client.client_id)


def arm_link(app: Any, hardware: Any, operator: FakeClient) -> None:
    """The operator's Arm device click in the Hardware panel, until the link says ARMED."""
    from console.panels.common.hardware import extensible_link_health

    user(hardware.arm_btn, operator)
    wait_for(lambda: (h := extensible_link_health(app)) is not None and h.armed, timeout=30.0,
             what=lambda: f"the link armed ({extensible_link_health(app)}; told {operator.notes})")


def test_path_preview_and_execute_on_mock_hardware(tab: Callable[..., Any]) -> None:
    app, client = tab("extensible", "mock")
    target, readout, jog, paths, hardware = panels(app)
    operator = FakeClient(client.client_id)  # the tab's clicks
    # Connecting never arms: the operator arms the in-process mock first.
    arm_link(app, hardware, operator)
    # Arm holds where the encoders are (the mock starts at the start pose) and makes that the
    # console's command, which the target rides on: type only once it has.
    armed_at = dk.tip_position(ROBOT, ExtensibleModel(ROBOT).initial()) * 1e3
    wait_for(lambda: np.abs(readout_tip(readout) - armed_at).max() <= 1.0,
             what="the command at the armed posture")
    wait_for(lambda: np.abs(np.array([float(h.value) for h in target.inputs]) - armed_at).max()
             <= 1.0, what="the target fields at the armed posture")
    start = np.array([100.0, 0.0, 300.0])
    type_target(client, target, start)
    wait_for(lambda: np.abs(readout_tip(readout) - start).max() <= 1.0, timeout=30.0,
             what=lambda: f"the tip at the start ({target.status.content})")
    user(paths.preview_btn, operator)
    wait_for(lambda: attr(paths.status.content, "data-state") == "previewed", timeout=60.0,
             what=lambda: f"the preview ({paths.status.content})")
    centre = readout_tip(readout) / 1e3
    end = build_path("linear", centre, 0.08, "xy")[-1] * 1e3  # default: linear, 80 mm, xy
    user(paths.execute_btn, operator)
    wait_for(lambda: attr(paths.status.content, "data-state") == "done", timeout=60.0,
             what=lambda: f"the run to finish ({paths.status.content}; told {operator.notes})")
    wait_for(lambda: np.abs(readout_tip(readout) - end).max() <= 1.0,
             what="the readout at the path's end")
    wait_for(lambda: np.linalg.norm(jog_tip(jog) - end) <= 1.0,
             what="the jog sliders at the path's end")


def test_emulator_console_measured_tip_reaches_a_typed_target(
        tab: Callable[..., Any], tmp_path: Path) -> None:
    """On the device emulator (a pty, the real serial stack) the readout shows what the
    encoders measure. The robot file is the shipped one with 0.5 s link timeout and watchdog
    (like tests/hw_bridge/test_extensible_runner.py): this test is about motion, not timing."""
    from console.panels.common.hardware import extensible_link_health

    robot_file = robot_copy("extensible", tmp_path,
                            {"bridge.watchdog_ms": 500, "bridge.link_timeout_ms": 500},
                            name="extensible")
    app, client = tab(str(robot_file), "emulator")
    target, readout, _, _, hardware = panels(app)
    operator = FakeClient(client.client_id)
    # serve.py connected the link at start, disarmed; the operator connects again and arms.
    user(hardware.connect_btn, operator)
    wait_for(lambda: (h := extensible_link_health(app)) is not None and h.state == "inactive",
             timeout=30.0, what=lambda: f"the link configured ({extensible_link_health(app)})")
    assert "/dev/pts/" in extensible_link_health(app).port
    arm_link(app, hardware, operator)
    # The emulated arm powers up at the console's start pose and Arm holds where it is.
    initial = dk.tip_position(ROBOT, ExtensibleModel(ROBOT).initial()) * 1e3
    seen = [readout_tip(readout)]

    def still() -> bool:
        time.sleep(0.3)
        seen.append(readout_tip(readout))
        return bool(np.abs(seen[-1] - seen[-2]).max() <= 0.05)

    wait_for(still, timeout=30.0, what="the measured tip held still")
    start = seen[-1]
    assert np.abs(start - initial).max() <= 0.5
    candidates = [np.array(c) for c in ((80.0, 40.0, 300.0), (80.0, 40.0, 180.0),
                                        (60.0, -40.0, 420.0))]
    aim = max(candidates, key=lambda c: float(np.linalg.norm(c - start)))
    assert np.linalg.norm(aim - start) > 100.0
    assert solve_tip_ik(ROBOT, aim / 1e3).reachable
    t0 = time.monotonic()
    type_target(client, target, aim)
    samples: list[np.ndarray] = []

    def arrived() -> bool:
        time.sleep(0.02)
        samples.append(readout_tip(readout))
        return bool(np.abs(samples[-1] - aim).max() <= 1.0)

    wait_for(arrived, timeout=60.0,
             what=lambda: f"the measured tip at the target ({target.status.content})")
    elapsed = time.monotonic() - t0
    # Encoder-driven: no faster than the tip speed limit, and shown on the way (no jump).
    distance = float(np.linalg.norm(aim - start)) / 1e3
    assert elapsed >= 0.9 * distance / ROBOT.tip_speed, elapsed
    assert any(np.linalg.norm(p - start) > 20.0 and np.linalg.norm(p - aim) > 20.0
               for p in samples), "the readout never showed the arm between start and target"
    assert attr(target.status.content, "data-state") == "reachable"
    time.sleep(0.5)  # settled: the encoders hold there
    assert np.abs(readout_tip(readout) - aim).max() <= 1.0
