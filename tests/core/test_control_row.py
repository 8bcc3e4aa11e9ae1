"""Several objects in a row (core.control.row) on the simulated arm through core's control cycle:
every object is released at the bin in queue order, and a failing object is recorded with its
reason while the rest of the row goes on."""

import numpy as np
import pytest

from core import robots
from core.control.grasp_place import Phase, immediate
from core.control.params import BinParams
from core.control.row import ObjectRow, RowObject, bin_at, run_row
from core.control.sim import SoftArmSim
from core.control.sim_loop import SimLoop
from core.control.stack import ControlStack
from core.control.trials import bin_drop_point
from core.kinematics.planar import forward_kinematics, point_in_frame
from core.planning.grasp import plan_grasp

R = 0.0165
B, D, E = RowObject(-0.22, 0.20, R), RowObject(-0.16, 0.28, R), RowObject(-0.08, 0.33, R)
FAR = RowObject(-0.6, 0.1, R)  # 61 cm from the base: beyond any reach


@pytest.fixture(scope="module")
def arm():
    return robots.load("soft-arm")


def _armed_loop(arm, seed=1, stack_type=ControlStack, planner=None):
    """The simulated arm and an armed ``stack_type`` (planning at once: ``planner`` or
    plan_grasp) on a SimLoop."""
    sim = SoftArmSim(arm, seed=seed)
    stack = stack_type(arm, 0.01, planner or immediate(
        lambda req: plan_grasp(arm, req.kappa, req.center, req.radius)))
    loop = SimLoop(sim, stack, 0.01)
    loop.run(0.05)
    loop.arm()
    loop.run(0.5)
    return sim, loop


class _World:
    """Puts each object on the simulated table when its turn begins; notes where the released
    object lies (the check the trials make)."""

    def __init__(self, sim, arm):
        self.sim, self.placed, self.at_release = sim, [], []
        self.drop = bin_drop_point(arm, R)

    def place(self, obj):
        self.placed.append(obj)
        self.sim.place_object(obj.x, obj.y, obj.r)

    def check(self, obj):
        self.at_release.append((obj, self.sim.obj.xy.copy(), self.sim.captured))


def test_three_objects_are_released_at_the_bin_in_order(arm):
    sim, loop = _armed_loop(arm)
    world = _World(sim, arm)
    row = run_row(loop, ObjectRow([B, D, E], check_release=world.check), world.place, 300.0)
    assert row.state == "done" and row.progress() == "3/3 released"
    assert [o.status for o in row.outcomes] == ["released"] * 3
    assert [o.object for o in row.outcomes] == [B, D, E] == world.placed
    assert [o.index for o in row.outcomes] == [0, 1, 2]
    ends = [o.ended_s for o in row.outcomes]
    assert ends == sorted(ends) and all(o.started_s < o.ended_s for o in row.outcomes)
    for o in row.outcomes:
        assert o.reason is None and o.approach_s > 0 and o.return_s > 0
    # Each object left its spot and was put down at the bin (not still held).
    assert [a[0] for a in world.at_release] == [B, D, E]
    for obj, xy, captured in world.at_release:
        assert not captured
        assert np.hypot(*(xy - world.drop)) < BinParams.from_robot(arm).drop_radius_m
        assert np.hypot(xy[0] - obj.x, xy[1] - obj.y) > 0.05
    assert loop.control.phase == Phase.RELEASED.value  # the last one; nothing started after


def test_an_unreachable_object_fails_with_its_reason_and_the_others_are_released(arm):
    sim, loop = _armed_loop(arm)
    world = _World(sim, arm)
    row = run_row(loop, ObjectRow([B, FAR, E], check_release=world.check), world.place, 300.0)
    assert row.state == "done" and row.progress() == "2/3 released"
    assert [o.status for o in row.outcomes] == ["released", "failed", "released"]
    failed = row.outcomes[1]
    assert failed.object == FAR
    assert failed.reason.startswith("planner refused") and "out of reach" in failed.reason
    assert [a[0] for a in world.at_release] == [B, E]
    for _, xy, _ in world.at_release:
        assert np.hypot(*(xy - world.drop)) < BinParams.from_robot(arm).drop_radius_m


def test_an_object_never_seen_fails_at_its_time_limit_and_the_row_goes_on(arm):
    sim, loop = _armed_loop(arm)
    world = _World(sim, arm)

    def place(obj):  # the first object is missing from the table (the mocap never sees it)
        if obj is B:
            sim.remove_object()
            world.placed.append(obj)
        else:
            world.place(obj)

    row = run_row(loop, ObjectRow([B, E], object_time_limit_s=40.0, check_release=world.check),
                  place, 200.0)
    assert [o.status for o in row.outcomes] == ["failed", "released"]
    assert row.outcomes[0].reason == "time limit 40 s reached in settling"
    assert row.outcomes[0].ended_s - row.outcomes[0].started_s == pytest.approx(40.0, abs=0.02)


def test_a_release_that_misses_the_bin_is_a_failure_with_the_check_s_reason(arm):
    sim, loop = _armed_loop(arm)
    row = run_row(loop, ObjectRow([B], check_release=lambda o: "not in the bin"),
                  lambda o: sim.place_object(o.x, o.y, o.r), 100.0)
    (o,) = row.outcomes
    assert o.status == "failed" and o.reason == "not in the bin" and row.progress() == "0/1 released"


def test_operator_stop_holds_the_arm_and_skips_the_rest_with_the_reason(arm):
    sim, loop = _armed_loop(arm)
    row = ObjectRow([B, D, E])
    sim.place_object(B.x, B.y, B.r)
    loop.submit(lambda s, t: row.start(s, t))
    loop.run(8.0, until=lambda c: c.phase == Phase.APPROACH.value)
    assert row.progress() == "object 1 of 3"
    row.stop(loop.stack, loop.t)
    for _ in range(100):
        t = loop.t
        control = loop.tick()
        assert row.after_tick(loop.stack, t) is None
    assert control.phase == Phase.STOPPED.value and control.reason == "operator STOP"
    assert row.state == "stopped" and loop.stack.machine.bin is arm.bin
    assert [(o.status, o.reason) for o in row.outcomes] == [
        ("failed", "operator STOP"), ("skipped", "row stopped: operator STOP"),
        ("skipped", "row stopped: operator STOP")]


def test_a_disarm_or_re_arm_under_the_row_ends_it_with_the_reason(arm):
    sim, loop = _armed_loop(arm)
    row = ObjectRow([B, E])
    sim.place_object(B.x, B.y, B.r)
    loop.submit(lambda s, t: row.start(s, t))
    loop.run(1.0)
    loop.arm()  # the operator arms again: the machine is back to idle
    for _ in range(3):
        t = loop.t
        loop.tick()
        row.after_tick(loop.stack, t)
    assert row.state == "stopped" and row.reason == "the grasp-and-place task was reset"
    assert [o.status for o in row.outcomes] == ["failed", "skipped"]
    sim, loop = _armed_loop(arm)
    row = ObjectRow([B, E])
    sim.place_object(B.x, B.y, B.r)
    loop.submit(lambda s, t: row.start(s, t))
    loop.run(1.0)
    loop.submit(lambda s, t: s.device_fault(t, "link lost"))
    t = loop.t
    loop.tick()
    row.after_tick(loop.stack, t)
    assert row.state == "stopped" and row.reason == "link lost"
    assert [(o.status, o.reason) for o in row.outcomes] == [
        ("failed", "link lost"), ("skipped", "row stopped: link lost")]


def test_a_custom_bin_configuration_is_where_the_objects_go(arm):
    sim, loop = _armed_loop(arm)
    bend = BinParams(np.array([0.0, 0.0, 0.0, 0.0, 2.0, 2.0]), 0.05)
    row = run_row(loop, ObjectRow([B], bin_params=bend), lambda o: sim.place_object(o.x, o.y, o.r),
                  100.0)
    assert row.outcomes[0].released
    m = loop.stack.machine
    assert np.hypot(*(m.palm(loop.stack.kappa_meas) - m.palm(bend.kappa))) <= m.p.release_distance_m
    assert m.bin is arm.bin  # the row's bin was for the row only


def test_bad_rows_are_refused_with_a_message(arm):
    with pytest.raises(ValueError, match="at least one object"):
        ObjectRow([])
    with pytest.raises(ValueError, match="radius"):
        RowObject(0.1, 0.2, 0.0)
    with pytest.raises(ValueError, match="finite"):
        RowObject(float("nan"), 0.2, 0.01)
    stack = ControlStack(arm, 0.01, immediate(lambda req: None))
    with pytest.raises(RuntimeError, match="not armed"):
        ObjectRow([B]).start(stack, 0.0)


def test_a_bin_placed_on_the_table_holds_the_object_over_that_point(arm):
    for x, y in ((0.15, 0.25), (-0.10, 0.30), (0.20, 0.10)):
        b = bin_at(arm, x, y)
        assert b.kappa.shape == (arm.n_segments,)
        assert np.all(np.abs(b.kappa) <= arm.kappa_max + 1e-9)
        tip = forward_kinematics(b.kappa, arm.lengths, arm.base_pose)[-1]  # independent FK
        held = point_in_frame(tip, (arm.gripper.w_off_along, 2 * arm.gripper.g_off + R))
        assert np.hypot(held[0] - x, held[1] - y) < 0.002
    with pytest.raises(ValueError, match=r"The bin at \(600, 100\) mm is out of reach"):
        bin_at(arm, 0.6, 0.1)
    with pytest.raises(ValueError, match=r"The bin at \(0, 0\) mm is on the arm's base"):
        bin_at(arm, 0.0, 0.0)  # on the base
    with pytest.raises(ValueError, match="finite"):
        bin_at(arm, float("nan"), 0.2)


def test_a_row_goes_to_a_bin_the_operator_placed(arm):
    sim, loop = _armed_loop(arm)
    spot = (0.15, 0.25)  # right of the arm, away from the robot file's (straight) bin
    world = _World(sim, arm)
    row = run_row(loop, ObjectRow([B, E], bin_params=bin_at(arm, *spot), check_release=world.check),
                  world.place, 200.0)
    assert [o.status for o in row.outcomes] == ["released", "released"]
    for _, xy, captured in world.at_release:
        assert not captured
        assert np.hypot(xy[0] - spot[0], xy[1] - spot[1]) < BinParams.from_robot(arm).drop_radius_m
        assert np.hypot(*(xy - world.drop)) > 0.1  # not at the default bin


def _refusing_planner(arm, blocked, always=False):
    """plan_grasp, except that it refuses ``blocked`` (as the obstacle planner words it) while
    another object waits on the table (an obstacle named "object j"), or always."""
    from core.planning.feasibility import GraspRefused

    def plan(req):
        waiting = [o.name for o in req.obstacles if o.name.startswith("object ")]
        at_blocked = np.hypot(req.center[0] - blocked.x, req.center[1] - blocked.y) < 0.005
        if at_blocked and (waiting or always):
            raise GraspRefused("blocked", f"No approach keeps 0 mm clear of "
                                          f"{waiting[0] if waiting else 'object 2'}.")
        return plan_grasp(arm, req.kappa, req.center, req.radius)
    return immediate(plan)


def test_an_object_blocked_by_a_waiting_one_waits_behind_the_rest(arm):
    # B's way is blocked while D still lies on the table: D is taken first, then B (the order
    # a person would choose), and the outcomes stay in queue order.
    sim, loop = _armed_loop(arm, planner=_refusing_planner(arm, B))
    world = _World(sim, arm)
    row = run_row(loop, ObjectRow([B, D], check_release=world.check), world.place, 300.0)
    assert row.state == "done" and row.progress() == "2/2 released"
    assert world.placed == [B, D, B]  # B's turn, D's, B's again
    assert [(o.index, o.status, o.reason) for o in row.outcomes] == [
        (0, "released", None), (1, "released", None)]
    assert [a[0] for a in world.at_release] == [D, B]


def test_an_object_still_refused_after_waiting_fails_once(arm):
    sim, loop = _armed_loop(arm, planner=_refusing_planner(arm, B, always=True))
    world = _World(sim, arm)
    row = run_row(loop, ObjectRow([B, D], check_release=world.check), world.place, 300.0)
    assert row.state == "done" and row.progress() == "1/2 released"
    assert world.placed == [B, D, B]
    (b, d) = row.outcomes
    assert (b.index, b.status) == (0, "failed") and "object 2" in b.reason
    assert (d.index, d.status) == (1, "released")
