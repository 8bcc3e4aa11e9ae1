"""Certified paths around obstacles (#17.1): the carry to the bin and the long way round to a
grasp keep the set clearance. Checked independently of the certificate: dense sampling of
core.kinematics.planar's forward kinematics (arm body, straight gripper, held object) along
every straight line in kappa the controller follows, and the simulated arm at every tick."""

import numpy as np
import pytest

from core import robots
from core.control.grasp_place import PlanRequest, immediate
from core.control.planner_spec import plan_request
from core.control.row import ObjectRow, RowObject, bin_at
from core.control.sim import SoftArmSim
from core.control.sim_loop import SimLoop
from core.control.stack import ControlStack
from core.kinematics import planar
from core.planning.arm_model import ArmModel
from core.planning.clear_path import (HELD_SLACK, ClearPathProblem, ClearPathRefused,
                                      HeldObject, clear_path)
from core.planning.grasp import GraspPlanner, GraspRefused, Obstacle
from core.planning.obstacle_planning import plan_around
from core.planning.obstacles import GripperShape
from core.planning.sides import plan_grasp_sided
from tests.core.test_obstacles import dense_gap, lines
from tests.robot_files import QUICK_MOTION, robot_copy

ARM = robots.load("soft-arm")
MODEL = ArmModel.from_robot(ARM)
GRIP = GripperShape.from_robot(ARM)
R = 0.0165
OBJECT = (-0.20, 0.20)
BIN = (-0.12, 0.10)
# Between the grasp pose and the bin pose: the straight carry sweeps the gripper through it.
BEHIND = Obstacle("Obstacle 1", -0.25, 0.27, 0.015)
CLEARANCE = 0.010


def held_gap(kappas, obstacle, side="left"):
    """Gap between the held object (radius R at the closing finger) and the obstacle."""
    tip = planar.forward_kinematics(kappas, ARM.lengths, ARM.base_pose)[..., -1, :]
    g = ARM.gripper
    normal = 2 * g.g_off + R
    xy = planar.point_in_frame(tip, (g.w_off_along, normal if side == "left" else -normal))
    return np.hypot(xy[..., 0] - obstacle.x, xy[..., 1] - obstacle.y) - obstacle.r - R


def dense(path, samples=401):
    tau = np.linspace(0.0, 1.0, samples)
    return path[:-1, None, :] + tau[:, None] * (path[1:] - path[:-1])[:, None, :]


@pytest.fixture(scope="module")
def grasp():
    plan = plan_grasp_sided(ARM, np.zeros(6), OBJECT, R, obstacles=[BEHIND],
                            clearance=CLEARANCE)
    assert plan.success
    return plan


@pytest.fixture(scope="module")
def bin_params():
    return bin_at(ARM, *BIN)


def _problem(start, obstacles=(BEHIND,), held=True):
    return ClearPathProblem(MODEL, GRIP, obstacles, CLEARANCE, 0.003,
                            HeldObject.at_finger(ARM, R, "left") if held else None, start)


def test_the_carry_goes_round_an_obstacle_the_straight_carry_sweeps_through(grasp, bin_params):
    start, goal = grasp.kappas[-1], bin_params.kappa
    straight = dense(np.array([start, goal]))
    assert min(dense_gap(straight, BEHIND).min(), held_gap(straight, BEHIND).min()) < 0.0
    path = clear_path(_problem(start), start, goal, goal_name="the bin pose")
    assert not path.straight and len(path.kappas) >= 3
    np.testing.assert_array_equal(path.kappas[0], start)
    np.testing.assert_array_equal(path.kappas[-1], goal)
    assert np.all(np.abs(path.kappas) <= ARM.kappa_max + 1e-12)  # lines stay in the box
    ks = dense(path.kappas)
    assert dense_gap(ks, BEHIND).min() >= CLEARANCE - 1e-9
    held_now = float(held_gap(start, BEHIND))
    assert held_gap(ks, BEHIND).min() >= min(CLEARANCE, held_now - HELD_SLACK) - 1e-9
    assert np.all(path.bound >= 0.0)
    # Deterministic: the same request gives the same path.
    again = clear_path(_problem(start), start, goal, goal_name="the bin pose")
    np.testing.assert_array_equal(again.kappas, path.kappas)


def test_a_clear_straight_line_is_kept_as_it_is(grasp, bin_params):
    far = Obstacle("Far", 0.30, 0.05, 0.02)
    start, goal = grasp.kappas[-1], bin_params.kappa
    path = clear_path(_problem(start, (far,)), start, goal)
    assert path.straight
    np.testing.assert_array_equal(path.kappas, [start, goal])


def test_a_goal_inside_the_clearance_is_refused_naming_the_obstacle(grasp, bin_params):
    goal = bin_params.kappa
    tip = planar.forward_kinematics(goal, ARM.lengths, ARM.base_pose)[-1]
    on_bin = Obstacle("Cup", float(tip[0]), float(tip[1]) - 0.05, 0.01)
    gap = dense_gap(goal[None], on_bin).min()
    assert gap < CLEARANCE        # the bin pose's gripper comes this close to the cup
    with pytest.raises(ClearPathRefused) as info:
        clear_path(_problem(grasp.kappas[-1], (on_bin,), held=False), grasp.kappas[-1], goal,
                   goal_name="the bin pose")
    assert info.value.obstacle == "Cup" and info.value.reason == "obstacle"
    assert str(info.value).startswith("The bin pose is too close to Cup")


def test_no_path_within_the_budget_is_refused_naming_the_obstacle(grasp):
    # From the left of the arm to a bin pose on its right, under an obstacle just above the
    # base: every motion would have to sweep the arm through it.
    right = bin_at(ARM, 0.18, 0.22).kappa_for(grasp.side)
    wall = Obstacle("Wall", 0.0, 0.30, 0.03)
    with pytest.raises(ClearPathRefused) as info:
        clear_path(_problem(grasp.kappas[-1], (wall,)), grasp.kappas[-1], right, budget_s=0.3)
    assert info.value.obstacle == "Wall" and "No motion found" in str(info.value)


def test_a_plan_request_with_a_bin_gets_its_carry_and_a_blocked_bin_is_refused(grasp,
                                                                              bin_params):
    req = PlanRequest(np.zeros(6), np.array(OBJECT), R, (BEHIND,), CLEARANCE, bin_params)
    plan = plan_request(plan_grasp_sided, ARM, req)
    assert plan.carry is not None and len(plan.carry) >= 2
    np.testing.assert_array_equal(plan.carry[-1], bin_params.kappa_for(plan.side))
    path = np.vstack([plan.kappas[-1:], plan.carry])
    assert dense_gap(dense(path), BEHIND).min() >= CLEARANCE - 1e-9
    tip = planar.forward_kinematics(bin_params.kappa, ARM.lengths, ARM.base_pose)[-1]
    cup = Obstacle("Cup", float(tip[0]), float(tip[1]), 0.01)
    with pytest.raises(GraspRefused, match="Carry to the bin: The bin pose is too close to Cup"):
        plan_request(plan_grasp_sided, ARM, PlanRequest(np.zeros(6), np.array(OBJECT), R,
                                                        (BEHIND, cup), CLEARANCE, bin_params))


def test_a_bin_too_close_to_an_obstacle_is_refused_before_anything_moves(bin_params):
    stack = ControlStack(ARM, 0.01, immediate(lambda req: None))
    tip = planar.forward_kinematics(bin_params.kappa, ARM.lengths, ARM.base_pose)[-1]
    stack.machine.bin = bin_params
    stack.set_obstacles([Obstacle("Cup", float(tip[0]), float(tip[1]), 0.01)], CLEARANCE)
    with pytest.raises(ValueError, match="The bin pose is too close to Cup"):
        stack.machine.start(0.0)
    assert stack.machine.phase.value == "idle" and not stack.machine.events


def test_a_row_to_a_bin_too_close_to_an_obstacle_is_refused_before_it_starts(bin_params):
    stack = ControlStack(ARM, 0.01, immediate(lambda req: None))
    stack.armed = True  # what the row looks at; nothing is stepped here
    tip = planar.forward_kinematics(bin_params.kappa_right, ARM.lengths, ARM.base_pose)[-1]
    stack.set_obstacles([Obstacle("Cup", float(tip[0]), float(tip[1]), 0.01)], CLEARANCE)
    row = ObjectRow([RowObject(*OBJECT, R)], bin_params)
    with pytest.raises(ValueError, match="The bin pose is too close to Cup"):
        row.start(stack, 0.0)
    assert row.state == "idle" and stack.machine.bin is ARM.bin
    assert stack.machine.phase.value == "idle" and not stack.machine.events


def test_the_simulated_carry_keeps_the_clearance_to_a_bin_behind_an_obstacle(bin_params,
                                                                            tmp_path):
    arm = robots.load(robot_copy("soft-arm", tmp_path, QUICK_MOTION))  # same arm, faster
    sim = SoftArmSim(arm, seed=2)
    sim.place_object(*OBJECT, R)
    plans = []

    def planner(req):
        plans.append(plan_request(plan_grasp_sided, arm, req))
        return plans[-1]

    stack = ControlStack(arm, 0.01, immediate(planner))
    loop = SimLoop(sim, stack, 0.01)
    loop.run(0.05)
    loop.arm()
    loop.run(0.5)
    stack.machine.bin = bin_params
    stack.set_obstacles([BEHIND], CLEARANCE)
    loop.submit(lambda s, t: s.start(t))
    arm_gap = {"approach": np.inf, "move_to_bin": np.inf}
    held = np.inf
    end = None
    for k in range(9000):
        end = loop.tick()
        if end is not None and end.phase in arm_gap and k % 3 == 0:
            arm_gap[end.phase] = min(arm_gap[end.phase],
                                     float(dense_gap(sim.kappa[None], BEHIND).min()))
            if end.phase == "move_to_bin" and sim.obj is not None:
                held = min(held, float(np.hypot(*(sim.obj.xy - (BEHIND.x, BEHIND.y)))
                                       - BEHIND.r - sim.obj.radius))
        if end is not None and end.phase in ("released", "stopped"):
            break
    assert end.phase == "released", end.reason
    (plan,) = plans
    assert len(plan.carry) >= 2                        # it went round, not straight
    assert arm_gap["move_to_bin"] >= CLEARANCE, arm_gap
    assert arm_gap["approach"] >= CLEARANCE / 2, arm_gap
    assert held > 0.0                                  # the held object never touched it
    assert any("carry: target 2/" in e for _, e in stack.machine.events)


def test_the_long_way_round_plans_a_spot_the_local_search_refused():
    planner = GraspPlanner(ARM)
    center, wall = (-0.20, 0.36), Obstacle("Obstacle 1", -0.11, 0.36, 0.015)
    km = np.zeros(6)
    with pytest.raises(GraspRefused, match="Obstacle 1 is in the way"):
        plan_around(planner, km, center, R, None, None, (wall,), CLEARANCE,
                    global_search=False)
    plan = plan_around(planner, km, center, R, None, None, (wall,), CLEARANCE)
    assert plan.success and plan.inserted.any()
    np.testing.assert_array_equal(plan.kappa_meas, km)
    ks = lines(plan)
    assert dense_gap(ks, wall).min() >= CLEARANCE - 1e-9
    # The object: the arm body never enters it (the gripper reaches around it).
    bb = planar.sample_backbone(ks, ARM.lengths, 64, ARM.base_pose)
    body = np.hypot(bb[..., 0] - center[0], bb[..., 1] - center[1]) - ARM.half_width - R
    assert body.min() >= -1e-9
    # Algorithm 1's final waypoint on the final circle, within the curvature limits.
    assert plan.radii[-1] == pytest.approx(R + ARM.gripper.g_off, abs=1e-9)
    assert np.all(np.abs(plan.kappas) <= ARM.kappa_max + 1e-9)


def test_a_measured_start_just_past_a_curvature_limit_is_planned_from_that_limit(grasp):
    """The measured arm sits a little past a limit after a carry that ended there (noise,
    overshoot): the next object's plan starts from the limit; far past it is refused, naming
    the segment (a row's second object failed with "the start is outside the curvature
    limits")."""
    from core.planning.clear_path import LIMIT_SLACK, within_limits

    start = np.clip(grasp.kappas[-1], MODEL.lo, MODEL.hi).copy()
    start[3] = MODEL.lo[3] - 0.5 * LIMIT_SLACK
    got = within_limits(MODEL, start)
    assert got[3] == MODEL.lo[3] and np.array_equal(np.delete(got, 3), np.delete(start, 3))
    path = clear_path(_problem(start, obstacles=(), held=False), start, np.zeros(6))
    assert np.array_equal(path.kappas[0], got) and np.array_equal(path.kappas[-1], np.zeros(6))
    start[3] = MODEL.lo[3] - 1.5 * LIMIT_SLACK
    with pytest.raises(ValueError, match=r"segment 4: .* limits"):
        clear_path(_problem(start, obstacles=(), held=False), start, np.zeros(6))
