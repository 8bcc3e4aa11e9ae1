"""Grasp-and-place state machine (Fig. 3): settling, advancing, grasp/place, failures, STOP."""

import dataclasses

import numpy as np
import pytest

from core import robots
from core.control.fastkin import fk, point_in_pose
from core.control.grasp_place import GraspAndPlace, Observation, Phase, immediate
from core.control.params import StateMachineParams

DT = 0.01


@pytest.fixture(scope="module")
def arm():
    return robots.load("soft-arm")


@dataclasses.dataclass
class Plan:
    kappas: np.ndarray
    palm_poses: np.ndarray


def make_plan(arm, n=3):
    final = np.array([-2.0, 1.0, 4.0, 6.0, 6.0, 5.0])
    kappas = np.array([final * (i + 1) / n for i in range(n)])
    palms = []
    for k in kappas:
        tip = fk(k, arm.lengths, arm.base_pose)[-1]
        palms.append([*point_in_pose(tip, *arm.gripper.w_off), tip[2]])
    return Plan(kappas, np.array(palms))


def object_in_gripper(arm, kappa, radius=0.0165):
    tip = fk(kappa, arm.lengths, arm.base_pose)[-1]
    return np.array(point_in_pose(tip, arm.gripper.w_off_along, 2 * arm.gripper.g_off + radius))


class Driver:
    """Feeds observations tick by tick; the 'arm' jumps to whatever target was last set."""

    def __init__(self, machine, kappa, obj):
        self.m, self.kappa, self.obj, self.t = machine, np.array(kappa, float), obj, 0.0
        self.target = self.kappa.copy()
        self.log = []

    def tick(self, *, kappa="follow", obj="same", finished=True):
        self.t = round(self.t + DT, 6)
        if isinstance(kappa, str):
            kappa = self.kappa
        if isinstance(obj, str):
            obj = self.obj
        d = self.m.step(Observation(self.t, kappa, obj, 0.0165, finished))
        if d.kappa_target is not None:
            self.target = d.kappa_target.copy()
        self.log.append(d)
        return d

    def run(self, seconds, follow=True, **kw):
        for _ in range(round(seconds / DT)):
            d = self.tick(**kw)
            if follow:
                self.kappa = self.target.copy()
        return d


def machine(arm, planner, **changes):
    p = dataclasses.replace(StateMachineParams.from_robot(arm), **changes)
    from core.control.params import BinParams
    return GraspAndPlace(arm, p, BinParams.from_robot(arm), planner)


def test_full_sequence_settle_plan_approach_grasp_place_release(arm):
    plan = make_plan(arm)
    calls = []
    m = machine(arm, immediate(lambda req: calls.append(req) or plan))
    obj = object_in_gripper(arm, plan.kappas[-1])
    drv = Driver(m, np.zeros(6), obj)
    m.start(0.0)
    drv.run(1.99, follow=False)
    assert m.phase is Phase.SETTLING and not calls  # not yet still for 2 s
    d = drv.run(0.02, follow=False)
    assert calls and np.allclose(calls[0].center, obj) and calls[0].radius == 0.0165
    assert m.phase is Phase.APPROACH and np.allclose(drv.target, plan.kappas[0])
    # Follow the targets: waypoints advance one after another, then grasp.
    seen = []
    for _ in range(20):
        drv.kappa = drv.target.copy()
        d = drv.tick()
        seen.append((m.phase, m.waypoint))
        if m.phase is Phase.GRASP:
            break
    assert [w for p, w in seen if p is Phase.APPROACH][:2] == [1, 2]
    assert m.phase is Phase.GRASP and d.gripper_closed
    # The object moves with the gripper from now on (it is held).
    drv.run(m.p.grasp_time_s + 0.02, follow=False)
    assert m.phase is Phase.MOVE_TO_BIN and np.allclose(drv.target, m.bin.kappa)
    # Carry: move part of the way (palm far from the bin): no release yet.
    drv.kappa = plan.kappas[-1] * 0.5
    drv.obj = object_in_gripper(arm, drv.kappa)
    drv.tick()
    assert m.phase is Phase.MOVE_TO_BIN
    # Within 1 cm of the bin's palm position: release.
    drv.kappa = np.full(6, 0.05)
    assert np.hypot(*(m.palm(drv.kappa) - m.palm(m.bin.kappa))) < 0.01
    drv.obj = object_in_gripper(arm, drv.kappa)
    d = drv.tick()
    assert m.phase is Phase.RELEASE and not d.gripper_closed
    drv.run(m.p.release_time_s + 0.02, follow=False)
    assert m.phase is Phase.RELEASED and m.reason is None
    assert m.approach_s is not None and m.return_s is not None


def test_moving_object_is_not_planned_for(arm):
    m = machine(arm, immediate(lambda req: make_plan(arm)))
    drv = Driver(m, np.zeros(6), np.array([-0.2, 0.2]))
    m.start(0.0)
    for i in range(400):  # creeping 3 mm every 0.5 s: never still for 2 s
        drv.obj = np.array([-0.2 + 0.003 * (i // 50), 0.2])
        drv.tick()
    assert m.phase is Phase.SETTLING


def test_waypoint_timeout_replans_then_stops_with_reason(arm):
    plan = make_plan(arm)
    m = machine(arm, immediate(lambda req: plan), max_replans=2, waypoint_timeout_s=1.0)
    drv = Driver(m, np.zeros(6), object_in_gripper(arm, plan.kappas[-1]))
    m.execute(plan, drv.obj, 0.0)
    drv.run(1.05, follow=False)  # the arm never moves
    assert m.replans == 1 and m.phase is Phase.APPROACH
    assert any("not reached" in e for _, e in m.events)
    drv.run(3.0, follow=False)
    assert m.phase is Phase.STOPPED
    assert "waypoint 1/3 not reached" in m.reason and "gave up after 2 re-plans" in m.reason


def test_timeout_only_counts_after_the_reference_arrived(arm):
    plan = make_plan(arm)
    m = machine(arm, immediate(lambda req: plan), waypoint_timeout_s=1.0)
    drv = Driver(m, np.zeros(6), object_in_gripper(arm, plan.kappas[-1]))
    m.execute(plan, drv.obj, 0.0)
    drv.run(5.0, follow=False, finished=False)  # reference still moving: no timeout
    assert m.replans == 0 and m.phase is Phase.APPROACH


def test_object_moved_during_approach_replans_after_settling(arm):
    plan = make_plan(arm)
    m = machine(arm, immediate(lambda req: plan))
    drv = Driver(m, np.zeros(6), object_in_gripper(arm, plan.kappas[-1]))
    m.execute(plan, drv.obj, 0.0)
    drv.tick()
    drv.obj = drv.obj + [0.02, 0.0]
    d = drv.tick()
    assert m.phase is Phase.SETTLING and d.hold_reference
    assert any("object moved 20 mm" in e for _, e in m.events)


def test_tracking_lost_holds_then_stops(arm):
    plan = make_plan(arm)
    m = machine(arm, immediate(lambda req: plan))
    drv = Driver(m, np.zeros(6), object_in_gripper(arm, plan.kappas[-1]))
    m.execute(plan, drv.obj, 0.0)
    assert drv.tick().kappa_target is not None  # execute hands out the first waypoint
    d = drv.tick(kappa=None)
    assert d.freeze and m.phase is Phase.APPROACH  # short occlusion: hold, keep going
    drv.tick()
    assert m.phase is Phase.APPROACH
    for _ in range(round(m.p.tracking_timeout_s / DT) + 1):
        d = drv.tick(kappa=None)
    assert m.phase is Phase.STOPPED and d.freeze and "tracking lost" in m.reason


def test_planner_refusal_and_asynchronous_planning(arm):
    class GraspRefused(ValueError):
        pass

    def refuse(req):
        raise GraspRefused("object out of reach")

    m = machine(arm, immediate(refuse))
    drv = Driver(m, np.zeros(6), np.array([0.5, 0.5]))
    m.start(0.0)
    drv.run(2.1, follow=False)
    assert m.phase is Phase.STOPPED and m.reason == "planner refused: object out of reach"

    class Pending:
        ready = False

        def done(self):
            return self.ready

        def result(self):
            return make_plan(arm)

    handle = Pending()
    m = machine(arm, lambda req: handle)
    drv = Driver(m, np.zeros(6), np.array([-0.2, 0.2]))
    m.start(0.0)
    d = drv.run(2.5, follow=False)
    assert m.phase is Phase.PLANNING and d.hold_reference  # ticks go on while planning
    handle.ready = True
    drv.tick()
    assert m.phase is Phase.APPROACH


def test_stop_freezes_with_a_reason(arm):
    plan = make_plan(arm)
    m = machine(arm, immediate(lambda req: plan))
    drv = Driver(m, np.zeros(6), object_in_gripper(arm, plan.kappas[-1]))
    m.execute(plan, drv.obj, 0.0)
    drv.tick()
    m.stop(drv.t)
    for _ in range(3):
        d = drv.tick()
        assert m.phase is Phase.STOPPED and d.freeze and d.reason == "operator STOP"
        assert d.kappa_target is None


def test_object_not_in_gripper_after_grasp_reopens_and_replans(arm):
    plan = make_plan(arm)
    m = machine(arm, immediate(lambda req: plan))
    far = object_in_gripper(arm, plan.kappas[-1]) + [0.0, 0.0]
    drv = Driver(m, np.zeros(6), far)
    m.execute(plan, far, 0.0)
    for _ in range(10):
        drv.kappa = drv.target.copy()
        drv.tick()
    assert m.phase is Phase.GRASP
    drv.obj = far + [0.03, 0.03]  # pushed away by the closing gripper; still near the plan
    m.plan_center = drv.obj.copy()
    drv.run(m.p.grasp_time_s + 0.02, follow=False)
    assert m.phase is Phase.SETTLING and not m.gripper_closed
    assert any("not in the gripper" in e for _, e in m.events)


def _carrying(arm, carry, **changes):
    """A machine in MOVE_TO_BIN with ``carry`` as its targets (the arm still at the grasp)."""
    plan = make_plan(arm)
    plan.carry = np.asarray(carry, float)   # what plan_carry adds to a plan
    m = machine(arm, immediate(lambda req: plan), **changes)
    drv = Driver(m, np.zeros(6), object_in_gripper(arm, plan.kappas[-1]))
    m.execute(plan, drv.obj, 0.0)
    for _ in range(200):   # the arm follows each approach target at once
        drv.tick()
        drv.kappa = drv.target.copy()
        if m.phase is Phase.GRASP:
            break
    drv.run(m.p.grasp_time_s + 0.02, follow=False)
    assert m.phase is Phase.MOVE_TO_BIN
    return m, drv


def test_a_carry_longer_than_move_timeout_is_not_cut_short_while_its_reference_moves(arm):
    """The reference moves at the trajectory's rate limits (0.8 1/(m s): a 33 1/m change of a
    carry takes ~41 s): move_timeout_s counts from when it arrived, not from the target's start
    (a row of three into a bin on the other side stopped with "carry target 1/2 not reached
    within 40 s" while the arm was still following)."""
    mid = np.array([12.0, -16.0, -16.0, -16.0, -16.0, -16.0])
    m, drv = _carrying(arm, [mid, np.zeros(6)], move_timeout_s=2.0)
    drv.run(5.0, follow=False, finished=False)   # the reference is still on its way
    assert m.phase is Phase.MOVE_TO_BIN and m.carry.index == 0
    drv.run(1.99, follow=False, finished=True)   # it arrived; the arm has not
    assert m.phase is Phase.MOVE_TO_BIN
    drv.run(0.03, follow=False, finished=True)
    assert m.phase is Phase.STOPPED
    assert "carry target 1/2 not reached 2 s after the reference arrived" in m.reason
    err = np.max(np.abs(drv.kappa - mid))
    assert f"max |dkappa| {err:.2f} 1/m" in m.reason


def test_a_middle_carry_target_is_reached_within_advance_dkappa_not_passed(arm):
    """Unlike an intermediate approach waypoint (passed within pass_dkappa), a via of the
    carry is a corner around an obstacle: the arm must be within advance_dkappa of it on every
    segment (passing it within pass_dkappa cut a simulated carry's clearance to 8 mm of 10)."""
    mid = np.array([5.0, -5.0, -5.0, -5.0, -5.0, -5.0])
    m, drv = _carrying(arm, [mid, np.zeros(6)])
    assert m.p.pass_over and m.p.pass_dkappa > m.p.advance_dkappa
    drv.kappa = mid + np.array([0, 0, 0, 0, 0, (m.p.advance_dkappa + m.p.pass_dkappa) / 2])
    drv.obj = object_in_gripper(arm, drv.kappa)   # held: it moves with the gripper
    drv.tick(finished=True)
    assert m.phase is Phase.MOVE_TO_BIN and m.carry.index == 0
    drv.kappa = mid + np.array([0, 0, 0, 0, 0, 0.9 * m.p.advance_dkappa])
    drv.obj = object_in_gripper(arm, drv.kappa)
    d = drv.tick(finished=True)
    assert m.carry.index == 1 and np.allclose(d.kappa_target, np.zeros(6))
