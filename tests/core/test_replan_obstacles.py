"""The controller's re-plans keep the obstacles' clearance, like its first plan (#17.1 gap).

The state machine re-plans from the measured arm when the object moved or a waypoint timed out.
Its plan requests carried no obstacles, so a re-plan ran the plain Algorithm 1 straight through
an obstacle the operator had placed. Here a plan made around an obstacle is executed on the
simulated arm through core's control cycle, the object is moved mid-approach, and the re-plan
must either keep the clearance (checked independently: dense forward kinematics of the arm and
the gripper along every straight line in kappa the controller follows, and the simulated arm's
own shape at every tick) or refuse, the task stopping with the reason naming the obstacle.
"""

import numpy as np
import pytest

from core import robots
from core.control.grasp_place import PlanRequest, immediate
from core.control.planner_spec import plan_request
from core.control.sim import SoftArmSim
from core.control.sim_loop import SimLoop
from core.control.stack import ControlStack
from core.planning.grasp import GraspRefused, Obstacle
from core.planning.sides import plan_grasp_sided
from tests.core.test_obstacles import dense_gap, lines

ARM = robots.load("soft-arm")
R = 0.0165
START = (-0.20, 0.20)
WALL = Obstacle("Obstacle 1", -0.07, 0.21, 0.015)  # between the straight arm and the object
CLEARANCE = 0.010


def _run(moved_to):
    """Execute the plan around WALL for the object at START; when the approach reaches its
    second waypoint, move the object to ``moved_to``. Returns (telemetry at the end, the
    planner's grasp calls as (request, plan or None, error or None), the simulated arm's smallest
    gap to WALL)."""
    calls = []

    def planner(req):
        if req.plan is not None:  # the executed plan's carry to the bin: not a grasp plan
            return plan_request(plan_grasp_sided, ARM, req)
        try:
            plan = plan_request(plan_grasp_sided, ARM, req)
        except GraspRefused as exc:
            calls.append((req, None, exc))
            raise
        calls.append((req, plan, None))
        return plan

    sim = SoftArmSim(ARM, seed=1)
    sim.place_object(*START, R)
    stack = ControlStack(ARM, 0.01, immediate(planner))
    loop = SimLoop(sim, stack, 0.01)
    loop.run(0.05)
    loop.arm()
    loop.run(0.5)
    first = plan_grasp_sided(ARM, stack.kappa_meas, START, R, obstacles=[WALL],
                             clearance=CLEARANCE)
    assert first.success
    stack.set_obstacles([WALL], CLEARANCE)
    loop.submit(lambda s, t: s.execute(first, START, t))
    moved, sim_gap, c = False, np.inf, None
    for k in range(12000):
        c = loop.tick()
        if k % 5 == 0:
            sim_gap = min(sim_gap, float(dense_gap(sim.kappa[None], WALL).min()))
        if not moved and c is not None and c.phase == "approach" and c.waypoint >= 1:
            sim.place_object(*moved_to, R)
            moved = True
        if c is not None and c.phase in ("released", "stopped"):
            break
    assert moved
    return c, calls, sim_gap


def test_a_re_plan_after_the_object_moved_keeps_the_clearance():
    end, calls, sim_gap = _run((-0.20, 0.22))
    assert end.phase == "released" and end.replans == 1, end.reason
    assert len(calls) == 1  # the execute's plan was given; the one call is the re-plan
    req, plan, _ = calls[0]
    assert req.obstacles == (WALL,) and req.clearance == CLEARANCE
    np.testing.assert_allclose(req.center, (-0.20, 0.22), atol=2e-3)
    # Without the obstacle the re-plan would sweep the arm through it (the test's premise) ...
    plain = plan_grasp_sided(ARM, req.kappa, req.center, req.radius)
    assert dense_gap(lines(plain), WALL).min() < 0.0
    # ... the re-plan keeps the clearance along every line from the arm's shape at the re-plan.
    assert plan.success and plan.obstacles == (WALL,) and plan.obstacle_margin == CLEARANCE
    np.testing.assert_array_equal(plan.kappa_meas, req.kappa)
    assert dense_gap(lines(plan), WALL).min() >= CLEARANCE - 1e-9
    # And the simulated arm (gripper included) never came near the obstacle.
    assert sim_gap >= CLEARANCE / 2


def test_a_re_plan_the_obstacle_makes_impossible_stops_with_the_reason():
    end, calls, sim_gap = _run((-0.22, 0.26))
    assert end.phase == "stopped"
    assert end.reason.startswith("planner refused: Obstacle 1 is in the way"), end.reason
    (req, plan, exc), = calls
    assert plan is None and exc.obstacle == "Obstacle 1" and req.obstacles == (WALL,)
    assert dense_gap(lines(plan_grasp_sided(ARM, req.kappa, req.center, req.radius)),
                     WALL).min() < 0.0  # a plain re-plan would have gone through it
    assert sim_gap >= CLEARANCE / 2


def test_plan_request_passes_obstacles_only_when_there_are_some():
    seen = []

    def four_args(robot, kappa, center, radius):
        seen.append((robot, radius))
        return "plain"

    req = PlanRequest(np.zeros(6), np.array(START), R)
    assert plan_request(four_args, ARM, req) == "plain"  # a planner that knows no obstacles
    with pytest.raises(TypeError):
        plan_request(four_args, ARM, PlanRequest(np.zeros(6), np.array(START), R, (WALL,), 0.01))


def test_bad_clearance_is_refused_and_changes_nothing():
    stack = ControlStack(ARM, 0.01, immediate(lambda req: None))
    stack.set_obstacles([WALL], CLEARANCE)
    for bad in (-0.01, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="clearance"):
            stack.set_obstacles([], bad)
    assert stack.machine.obstacles == (WALL,) and stack.machine.clearance == CLEARANCE
    stack.machine.reset()  # a new task keeps the scene's obstacles
    assert stack.machine.obstacles == (WALL,)
