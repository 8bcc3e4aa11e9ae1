"""With no bin placed, Execute and the row drop the objects at the robot file's ``[bin]``: the 3D
scene draws it there (dimmed, one box per finger, one label "robot file's bin" over them), at the drop points
worked out here in closed form (the shipped ``[bin]`` is the straight arm: the held object lies
2 g_off + r beside the tip's line, w_off_along beyond the tip), and hides it once a bin is placed."""

from __future__ import annotations

import numpy as np
import pytest
import viser

from console.core.table_bin import TableBin
from console.scene.bin_view import ROBOT_FILE_LABEL, BinView
from core.robots import load

SOFT = load("soft-arm")


@pytest.fixture()
def server():
    srv = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    yield srv
    srv.stop()


def test_the_robot_files_bin_is_drawn_until_a_bin_is_placed(server) -> None:
    assert SOFT.bin.kappa.tolist() == [0.0] * SOFT.n_segments  # the arm straight along +y
    r = SOFT.capture.nominal_object_radius
    bx, by = (float(v) for v in np.asarray(SOFT.base_pose)[:2])
    side = 2 * SOFT.gripper.g_off + r
    ahead = by + sum(SOFT.lengths) + SOFT.gripper.w_off_along
    expected = {"left": (bx - side, ahead), "right": (bx + side, ahead)}
    view = BinView(server.scene, SOFT)
    boxes, (label,) = view.defaults[:-1], view.defaults[-1:]
    assert len(boxes) == len(SOFT.gripper.sides) >= 1
    for s, box in zip(SOFT.gripper.sides, boxes):
        assert box.position[:2] == pytest.approx(expected[s], abs=1e-4)
        assert box.opacity is not None and box.opacity < 1.0 and box.visible
    # One label over the boxes: a label per finger's box ("(left finger)", "(right finger)",
    # 73 mm apart) overlapped in the demo's screenshots.
    assert label.text == ROBOT_FILE_LABEL and label.visible
    mid = np.mean([expected[s] for s in SOFT.gripper.sides], axis=0)
    assert label.position[:2] == pytest.approx(mid, abs=1e-4)
    view.draw(TableBin(0.15, 0.25, (0.0,) * SOFT.n_segments, SOFT.bin.drop_radius_m))
    assert not any(n.visible for n in view.defaults) and view.box.visible
    view.draw(None)
    assert all(n.visible for n in view.defaults) and not view.box.visible
