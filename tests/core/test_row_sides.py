"""A row with the two-finger gripper (``[gripper] fingers = "both"``): an object grasped by the
right finger drops at the bin as a left one does -- at the robot file's (straight) bin, at a bin
the operator placed on the table, and in ``python -m core.control.trials --objects-in-a-row``.

Independent expectations: the straight arm's right pocket by hand (base at the origin heading
+y, the gripper's right is +x: ``(2 g_off + r, N L + w_along)``), and a placed bin's point
itself; the placed bin's right-finger pose is checked with forward kinematics.
"""

import json

import numpy as np
import pytest

from core import robots
from core.control import trials
from core.control.grasp_place import immediate
from core.control.row import ObjectRow, RowObject, bin_at, run_row
from core.control.sim import SoftArmSim
from core.control.sim_loop import SimLoop
from core.control.stack import ControlStack
from core.control.trials.__main__ import main as trials_main
from core.kinematics.planar import forward_kinematics, point_in_frame
from core.planning.sides import plan_grasp_sided

ARM = robots.load("soft-arm")
R = ARM.capture.nominal_object_radius
G = ARM.gripper
_CX, _CY = trials.paper_locations()["C"]
RIGHT = RowObject(-_CX, _CY, R)  # spot C mirrored: the right finger's
LEFT = RowObject(-0.22, 0.20, R)  # spot B: the left finger's
DROP_RADIUS = ARM.bin.drop_radius_m


def _armed_loop(seed=1):
    sim = SoftArmSim(ARM, seed=seed)
    stack = ControlStack(ARM, 0.01, immediate(
        lambda req: plan_grasp_sided(ARM, req.kappa, req.center, req.radius)))
    loop = SimLoop(sim, stack, 0.01)
    loop.run(0.05)
    loop.arm()
    loop.run(0.5)
    return sim, loop


def _run(objects, bin_params=None):
    """Run the row; returns it and, per released object, (the finger that held it, where the
    object lay right after the release, whether it was still captured)."""
    sim, loop = _armed_loop()
    seen = []

    def check(obj):
        seen.append((loop.stack.machine.closing_side, sim.obj.xy.copy(), sim.captured))

    row = run_row(loop, ObjectRow(objects, bin_params=bin_params, check_release=check),
                  lambda o: sim.place_object(o.x, o.y, o.r), 150.0 * len(objects))
    return row, seen


def test_right_grasp_in_a_row_drops_at_the_straight_bin():
    assert "right" in G.sides  # the shipped arm has both fingers
    row, seen = _run([RIGHT, LEFT])
    assert [o.status for o in row.outcomes] == ["released", "released"], row.outcomes
    (side_r, xy_r, cap_r), (side_l, xy_l, cap_l) = seen
    assert (side_r, side_l) == ("right", "left") and not cap_r and not cap_l
    normal, along = 2 * G.g_off + R, ARM.n_segments * ARM.segment_length + G.w_off_along
    assert np.hypot(*(xy_r - (normal, along))) < DROP_RADIUS  # right pocket: +x
    assert np.hypot(*(xy_l - (-normal, along))) < DROP_RADIUS  # left pocket: -x


def test_a_placed_bin_holds_the_right_finger_object_over_its_point():
    for x, y in ((0.15, 0.25), (-0.10, 0.30), (0.20, 0.10)):
        b = bin_at(ARM, x, y)
        assert b.kappa_right is not None and np.all(np.abs(b.kappa_right) <= ARM.kappa_max + 1e-9)
        tip = forward_kinematics(b.kappa_right, ARM.lengths, ARM.base_pose)[-1]
        held = point_in_frame(tip, (G.w_off_along, -(2 * G.g_off + R)))  # right: -normal
        assert np.hypot(held[0] - x, held[1] - y) < 0.002
        np.testing.assert_array_equal(b.kappa_for("right"), b.kappa_right)
        np.testing.assert_array_equal(b.kappa_for("left"), b.kappa)


def test_right_grasp_in_a_row_drops_at_a_placed_bin():
    spot = (0.15, 0.25)
    row, seen = _run([RIGHT, LEFT], bin_at(ARM, *spot))
    assert [o.status for o in row.outcomes] == ["released", "released"], row.outcomes
    assert [s for s, _, _ in seen] == ["right", "left"]
    for _, xy, captured in seen:
        assert not captured and np.hypot(xy[0] - spot[0], xy[1] - spot[1]) < DROP_RADIUS


@pytest.mark.parametrize("bin_args", [[], ["--bin", "0.15", "0.25"]])
def test_trials_cli_row_counts_a_right_grasp_released_at_the_bin(capsys, bin_args):
    trials_main(["--objects-in-a-row", "2", "--json", "--time-limit", "80",
                 "--object", str(RIGHT.x), str(RIGHT.y), str(R),
                 "--object", str(LEFT.x), str(LEFT.y), str(R), *bin_args])
    out = json.loads(capsys.readouterr().out)
    assert [o["status"] for o in out["row"]] == ["released", "released"], out["row"]
    assert out["released"] == 2
