"""Lab robots that are not the shipped ones, in the console serve.py builds, without a browser:
the runtime takes its counts from the robot file.

``serve.build`` (what ``serve.py --robot FILE --hardware mock`` runs, in this process) for
tests/data/robots/soft-4x80mm.toml (four 80 mm segments) runs a full grasp-and-place from the
Control panel to ``released``, the panel showing one measured curvature per segment; for
tests/data/robots/extensible-3seg.toml (three tri-rack segments) a typed tip target is answered
reachable, the tip readout comes to it and the rack readout has a cell per rack of the file's
arm. Expectations come from the robot files (the object position scales with the arm; the tip
target is checked with the test's own call of the IK and forward kinematics). The soft arm's
client is a FakeClient driving the panels' callbacks; the extensible target is typed by a raw
websocket client, a real tab to the lease (was tests/browser/test_browser_custom_robots.py).
The four-segment arm moves as tests/robot_files.py QUICK_MOTION says (a test copy of its file).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest
from robot_files import QUICK_MOTION, robot_copy

from console.core.grasp_session import GraspSession
from core.kinematics import delta as dk
from core.kinematics.delta_ik import solve_tip_ik
from core.robots import load
from fakes import FakeClient, user
from tests.ws_client import RawClient, wait_for

# A patient link (0.5 s for a STATE and for the device's watchdog, not the shipped 40 / 50 ms):
# this test is about what the console and the control process do, not link timing, and the
# suite runs it beside another test on two busy cores (link gaps: benchmarks/link_gaps.py).
PATIENT_LINK = {"bridge.watchdog_ms": 500, "bridge.link_timeout_ms": 500}

DATA = Path(__file__).resolve().parents[1] / "data" / "robots"


@pytest.fixture
def served(served_console: Callable[..., Any],
           monkeypatch: pytest.MonkeyPatch) -> Callable[[Path], Any]:
    """``served(robot_file)``: the console serve.py builds for that file on mock hardware, not
    started (the lease would take control from this headless client; conftest
    ``served_console``)."""
    monkeypatch.setattr(GraspSession, "compute_reach", False)  # (no reach cache for these arms)
    return lambda robot_file: served_console(robot_file)


def test_four_segment_soft_arm_grasps_and_places(served: Callable[[Path], Any],
                                                 tmp_path: Path) -> None:
    from console.panels.soft_arm.control import ControlPanel
    from console.panels.soft_arm.objects import ObjectsPanel

    robot_file = robot_copy(DATA / "soft-4x80mm.toml", tmp_path, {**QUICK_MOTION, **PATIENT_LINK})
    arm = load(robot_file)
    assert arm.n_segments == 4
    total = arm.n_segments * arm.segment_length
    x, y = -0.53 * total, 0.53 * total  # up and to the left, within reach of this arm
    app = served(robot_file)
    objects, control = app.panel(ObjectsPanel), app.panel(ControlPanel)
    operator = FakeClient(1)
    app.access.take(operator.client_id, None, name="tester")
    user(objects.x, operator, x * 1e3)  # mm in the fields
    user(objects.y, operator, y * 1e3)
    (obj,) = wait_for(lambda: (v := app.grasp_session.view().objects)
                      and v[0].x == pytest.approx(x) and v[0].y == pytest.approx(y) and v,
                      what="Object 1 at the typed spot")

    def phase() -> str:
        view = control.ctl.view
        c = None if view is None else view.snapshot.control
        return "" if c is None else c.phase

    wait_for(lambda: phase() == "idle", timeout=30.0, what="the control process's first view")
    user(control.arm_btn, operator)
    wait_for(lambda: control.ctl.view.snapshot.control.armed, timeout=30.0,
             what=lambda: f"armed (told: {operator.notes})")
    user(control.execute.execute_btn, operator)
    wait_for(lambda: phase() in ("grasp", "move_to_bin"), timeout=60.0,
             what=lambda: f"grasping (told: {operator.notes})")
    c = control.ctl.view.snapshot.control
    assert c.kappa_meas is not None and len(c.kappa_meas) == 4  # one per segment of the file
    cells = re.findall(r'data-testid="kappa-meas-(\d+)"', control.kappa_md.content)
    assert cells == ["0", "1", "2", "3"]
    seen: set[str] = set()

    def released() -> bool:
        seen.add(phase())
        assert not seen & {"stopped", "idle"}, (seen, operator.notes)
        return phase() == "released"

    wait_for(released, timeout=60.0, what="released")
    assert not any(title in ("Not allowed", "Refused") for title, _ in operator.notes)


def readout_tip_mm(html: str) -> np.ndarray:
    """The tip readout's x, y, z (mm) as the page shows them."""
    cells = dict(re.findall(r'data-testid="tip-(\d)"[^>]*>(?:<code>)?([^<]*)<', html))
    return np.array([float(cells[str(k)].replace("⚠", "")) for k in range(3)])


def test_three_segment_extensible_arm_reaches_a_typed_target(
        served: Callable[[Path], Any]) -> None:
    from console.panels.common.readout import ReadoutPanel
    from console.panels.extensible.target import TargetPanel

    robot_file = DATA / "extensible-3seg.toml"
    arm = load(robot_file)
    assert arm.n_segments == 3
    target_mm = np.array([100.0, -50.0, 0.8 * arm.n_segments * arm.rack_max * 1e3])
    ik = solve_tip_ik(arm, target_mm / 1e3)
    assert ik.reachable and np.linalg.norm(dk.tip_position(arm, ik.delta) - target_mm / 1e3) < 1e-3
    app = served(robot_file)
    app.start()  # the motion to the target runs on the console's threads
    # A real websocket client (answering the lease's probes, as a tab does) types the target.
    tab = RawClient(app.server)
    try:
        app.access.take(tab.client_id, None, name="tester")
        target, readout = app.panel(TargetPanel), app.panel(ReadoutPanel)
        for handle, value in zip(target.inputs, target_mm):
            assert tab.update(handle._impl.uuid, value=float(value))
        assert tab.update(target.go._impl.uuid, value=True)  # x, y, z together
        check_reached(app, tab, target, readout, arm, target_mm)
    finally:
        tab.close()


def check_reached(app: Any, tab: RawClient, target: Any, readout: Any, arm: Any,
                  target_mm: np.ndarray) -> None:
    try:
        wait_for(lambda: np.abs(readout_tip_mm(readout.html.content) - target_mm).max() <= 1.0,
                 timeout=30.0, what="the tip readout at the target")
    except AssertionError as exc:
        raise AssertionError(f"{exc}: {readout_tip_mm(readout.html.content)}; status "
                             f"{target.status.content}") from None
    aimed = ",".join(f"{v:.1f}" for v in target_mm)
    status = target.status.content
    assert f'data-target-mm="{aimed}"' in status and 'data-state="reachable"' in status, status
    racks = re.findall(r'data-testid="rack-\d+-\d+" data-near-limit=', readout.html.content)
    assert len(racks) == 3 * arm.n_segments  # a rack readout per rack of the file's arm
    assert app.access.is_operator(tab.client_id)
