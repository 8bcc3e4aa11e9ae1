"""Execute says where the object goes: seen in a walk through the console, with no bin placed
Execute dropped the object at the robot file's ``[bin]`` (the arm straight), then not drawn,
so the operator could not tell where it would go. The Control panel's target line and the
Execute notification name the drop point of each finger (closed form below: the straight arm's
tip, the gripper's offsets), and once a bin is placed, that bin."""

from __future__ import annotations

from test_row_console import SOFT, place_scene, rig, show, view_with  # noqa: F401


def test_execute_names_the_robot_files_bin_until_a_bin_is_placed(rig) -> None:
    app, objects_panel, control, _, operator, _ = rig
    s = app.grasp_session
    assert SOFT.bin.kappa.tolist() == [0.0] * 6  # the shipped [bin]: the arm straight
    s.update("Object 1", r=0.02)
    # Straight along +y from the base: tip at the arm's length; the object held beside it,
    # 2 g_off + r to the finger's side, w_off_along beyond the tip.
    side = (2 * SOFT.gripper.g_off + 0.02) * 1e3
    ahead = (sum(SOFT.lengths) + SOFT.gripper.w_off_along) * 1e3
    expected = (f"no bin placed: into the robot file's bin (drawn dimmed on the table), dropped at "
                f"({-side:.0f}, {ahead:.0f}) mm (left finger) or ({side:.0f}, {ahead:.0f}) mm "
                f"(right finger); to choose, set Table click places: Bin (top of Operate) and "
                f"click the table")
    assert expected.startswith("no bin placed: into the robot file's bin (drawn dimmed on the table), dropped "
                               "at (-40, 411) mm")
    control.execute._show_target()
    assert expected in control.execute.target_md.content.replace("&#x27;", "'")
    show(control, view_with(armed=True))
    event = type("E", (), {"client": operator, "client_id": operator.client_id})()
    control.execute._execute(event)
    assert operator.notes[-1][0] == "Grasp-and-place" and expected in operator.notes[-1][1]
    place_scene(app, objects_panel, operator)
    s.select("Object 1")
    control.execute._show_target()
    assert "; into the bin at (150, 250) mm" in control.execute.target_md.content
    control.execute._execute(event)
    assert operator.notes[-1][1].endswith("; into the bin at (150, 250) mm")
