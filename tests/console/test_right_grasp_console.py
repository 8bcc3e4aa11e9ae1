"""The soft arm's Control panel grasps an object on the right of the arm, without a browser: the
console's Objects and Control panels on the real control process (simulated arm, two-finger
gripper) take an object typed at the paper's spot E mirrored across the arm's base line.

What tests/browser/test_browser_right_grasp.py read from the page is read here from the panels
and the published view: the typed position moves the selected object there; after Arm,
*Execute grasp-and-place* runs, and during the grasp the palm point (the readout's w_t, here
computed from the measured curvatures of the loop's view) is at the object, on the right of the
arm (x > 0); the state line then shows "released" -- which the state machine says only after it
saw the object held in the right finger's pocket and carried to the bin.

Independent expectations: the spot (the paper's E with x negated), the palm's offset from the
object's centre (g_off + r = 26.5 mm; at most the capture region's 53 mm: 55 mm allowed) and the
base heading +y (x > 0 is the right). The arm is a test copy of the soft arm that moves three
times faster with shorter waits (tests/robot_files.py QUICK_MOTION): the test is about which side
the gripper takes, not the shipped timing.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from console.panels.soft_arm.control import ControlPanel
from console.panels.soft_arm.objects import ObjectsPanel
from core.control.trials import paper_locations
from core.kinematics import planar
from fakes import FakeClient, user
from test_row_process import quick_soft_app  # noqa: F401 (a fixture: the same console)
from tests.ws_client import wait_for

RUN_TIMEOUT_S = 90.0
PALM_MM = 55.0


def palm_mm(robot: Any, kappa: np.ndarray) -> np.ndarray:
    """The palm point w_t (mm) of the arm with curvatures ``kappa``, as the readout shows it."""
    tip = planar.forward_kinematics(kappa, robot.lengths, robot.base_pose)[-1]
    return planar.point_in_frame(tip, robot.gripper.w_off) * 1e3


def test_execute_grasps_a_right_side_object_and_releases_it(quick_soft_app: Any) -> None:
    app = quick_soft_app
    objects, control = app.panel(ObjectsPanel), app.panel(ControlPanel)
    session = app.grasp_session
    x, y = paper_locations()["E"]
    spot = (-x, y)  # right of the arm
    assert spot[0] > 0 and np.allclose(app.robot.base_pose[:2], 0.0)
    assert math.isclose(app.robot.base_pose[2], math.pi / 2)  # heading +y: x > 0 is the right
    operator = FakeClient(1)
    app.access.take(operator.client_id, "tok", name="Alice")
    wait_for(lambda: control.ctl.view is not None and control.ctl.view.snapshot.control,
             timeout=30.0, what="the control process's first view")

    # The selected object (Object 1) typed to the spot, in mm, as the Objects panel's fields.
    user(objects.x, operator, round(spot[0] * 1e3))
    user(objects.y, operator, round(spot[1] * 1e3))
    wait_for(lambda: [(round(o.x, 3), round(o.y, 3)) for o in session.view().objects]
             == [(round(spot[0], 3), round(spot[1], 3))], what=lambda: f"Object 1 at {spot}")
    assert session.view().selected == "Object 1"

    user(control.arm_btn, operator)
    wait_for(lambda: control.ctl.view.snapshot.control.armed, timeout=30.0,
             what=lambda: f"armed (told the operator: {operator.notes})")
    user(control.execute.execute_btn, operator)

    def phase() -> str:
        return control.ctl.view.snapshot.control.phase

    end = time.monotonic() + RUN_TIMEOUT_S
    while (c := control.ctl.view.snapshot.control).phase not in ("grasp", "move_to_bin"):
        assert c.phase not in ("stopped", "released"), (c.phase, control.state_md.content)
        assert time.monotonic() < end, f"no grasp: {control.state_md.content}; {operator.notes}"
        time.sleep(0.02)
    palm = palm_mm(app.robot, c.kappa_meas)  # (the first frame of the grasp seen: one view)
    # The palm point is g_off + r = 26.5 mm beside the object's centre: on its right side.
    d = math.hypot(palm[0] - spot[0] * 1e3, palm[1] - spot[1] * 1e3)
    assert palm[0] > 0 and d < PALM_MM, (palm, d, control.state_md.content)

    while phase() != "released":
        assert phase() not in ("stopped", "idle"), (phase(), control.state_md.content)
        assert time.monotonic() < end, f"not released: {control.state_md.content}"
        time.sleep(0.05)
    wait_for(lambda: 'data-phase="released"' in control.state_md.content,
             what="the state line: released")
    assert "released" in control.state_md.content and control.ctl.view.snapshot.control.armed
    assert not any(title in ("Refused", "Not allowed") for title, _ in operator.notes), \
        operator.notes
