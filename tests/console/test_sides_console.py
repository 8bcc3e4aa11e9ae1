"""Both sides in the console (#17.2): the Trials panel's per-side table and bars, the Capture
panel's two maps, the plan layer's capture disc on the right finger's side, the two-finger
gripper drawing, and the shipped reachability map a hit for the console's request."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from console.app import ConsoleApp
from console.scene.gripper_mesh import GripperShape, gripper_vertices
from console.panels.soft_arm.capture import CapturePanel
from console.panels.soft_arm.trials import TrialsPanel, sides_html
from console.scene.plan_view import plan_geometry
from console.core.reach_job import SHIPPED_CACHE, ReachCache, ReachRequest
from core.control.trials import TrialResult, paper_locations
from core.planning.reachability import PLANNABLE
from core.planning.sides import plan_grasp_sided
from core.robots import load

SOFT = load("soft-arm")
REPO = Path(__file__).resolve().parents[2]


def test_trials_panel_runs_the_mirrored_spots_and_shows_success_per_side(server) -> None:
    app = ConsoleApp(SOFT, server, panels=(TrialsPanel,))
    panel = app.panel(TrialsPanel)
    assert panel.side.value == "Left (paper)"  # the paper's experiment unless asked
    panel.side.value = "Both"
    objects = panel.objects()
    assert [k for k, _ in objects] == list(paper_locations()) + [f"{k}'" for k in
                                                                  paper_locations()]
    for (_, left), (_, right) in zip(objects[:5], objects[5:]):
        assert right == pytest.approx((-left[0], left[1], left[2]))
    r = [0.1, 0.2, 0.0165]
    results = [TrialResult(r, True, None, 1, 1, side="left")] * 4 + [
        TrialResult(r, False, "x", 1, 1, side="left")] + [
        TrialResult(r, True, None, 1, 1, side="right")] * 5
    html = sides_html(results)
    rows = dict(re.findall(r"<tr data-side='(\w+)'><td>\w+</td><td>([\d/]+)</td>", html))
    assert rows == {"left": "4/5", "right": "5/5"}
    widths = [float(w) for w in re.findall(r"width='([\d.]+)' height='16' fill='#(?!eee)", html)]
    assert widths == pytest.approx([160 * 0.8, 160 * 1.0])


def test_capture_panel_characterises_both_fingers_and_says_they_mirror(server) -> None:
    app = ConsoleApp(SOFT, server, panels=(CapturePanel,))
    panel = app.panel(CapturePanel)
    assert panel.side.value == "Both"
    panel._run(SOFT.capture.nominal_object_radius, 0.01, 1, ("left", "right"))
    assert set(panel.maps) == {"left", "right"}, panel.summary.content
    left, right = panel.maps["left"], panel.maps["right"]
    assert left.successes == right.successes > 10
    # Independent reflection: cell (x, y) of the left map is cell (x, -y) of the right one.
    for j, y in enumerate(left.ys):
        jr = int(np.argmin(np.abs(right.ys + y)))
        assert abs(right.ys[jr] + y) < 1e-9
        np.testing.assert_array_equal(right.outcome[jr], left.outcome[j])
    text = panel.summary.content
    assert "**left finger:**" in text and "**right finger:**" in text
    assert "mirrored in **100%** of the cells" in text
    assert panel.drawing.content.count("<svg") == 2


def test_plan_layer_draws_the_capture_disc_on_the_closing_fingers_side() -> None:
    for x in (-0.13, 0.13):
        plan = plan_grasp_sided(SOFT, np.zeros(6), (x, 0.17), SOFT.capture.nominal_object_radius)
        g = plan_geometry(SOFT, plan, plan.n - 1, False)
        centre = g["capture"][0][0, :2]
        # The disc sits on the object the plan grasps (left or right finger alike).
        assert np.hypot(*(centre - plan.center)) < 2e-3, (plan.side, centre, plan.center)


def test_two_finger_gripper_is_drawn_as_a_mirrored_pair() -> None:
    shape = GripperShape.of(SOFT)
    assert shape.fingers == "both"
    one = GripperShape(shape.length, shape.half_width, shape.palm_length, shape.closed_turn)
    v1, _ = gripper_vertices(one, closed=False)
    v2, f2 = gripper_vertices(shape, closed=False)
    # Open: the pair has the one finger's outline (tip frame columns: left, up, along).
    np.testing.assert_allclose(v2.min(0), v1.min(0), atol=1e-6)
    np.testing.assert_allclose(v2.max(0), v1.max(0), atol=1e-6)
    assert f2.max() < len(v2)
    closed, _ = gripper_vertices(shape, closed=True)
    upper, lower = closed[: len(closed) // 2], closed[len(closed) // 2:]
    assert (upper[:, 1] >= -1e-9).all() and (lower[:, 1] <= 1e-9).all()  # stacked
    # Each finger curls toward its own side: the upper (left) to +left, the lower to -left.
    np.testing.assert_allclose(lower[:, 0], -upper[:, 0], atol=1e-6)
    assert upper[:, 0].max() > shape.half_width * 2 and lower[:, 0].min() < -shape.half_width * 2


def test_shipped_reach_map_is_the_consoles_request_and_covers_both_sides() -> None:
    # The request as the console makes it (ConsoleApp.table_rectangle on the default arm).
    stub = SimpleNamespace(robot=SOFT, model=SimpleNamespace(kind="planar"))
    stub.arm_reach = lambda: ConsoleApp.arm_reach(stub)
    x0, x1, y0, y1 = ConsoleApp.table_rectangle(stub)
    request = ReachRequest(SOFT.source, SOFT.capture.nominal_object_radius, (x0, x1), (y0, y1))
    reach = ReachCache(SHIPPED_CACHE).load(request)
    assert reach is not None, "run: python scripts/make_reach_cache.py"
    assert (reach.status[:, reach.xs < 0] == PLANNABLE).sum() > 100
    assert (reach.status[:, reach.xs > 0] == PLANNABLE).sum() > 100
    np.testing.assert_array_equal(reach.status, reach.status[:, ::-1])
    done = subprocess.run([sys.executable, "scripts/make_reach_cache.py", "--check"], cwd=REPO,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and "hit" in done.stdout, done.stdout + done.stderr
