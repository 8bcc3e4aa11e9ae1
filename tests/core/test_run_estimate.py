"""The time estimates the console shows (core.control.run_estimate) against the simulated arm on
core's simulated clock (SimLoop: 100 Hz of simulated time, no wall clock): the estimate made
before a grasp-and-place and the remaining time while it runs are within FACTOR of what the run
took, and the plan published as executing is the one the state machine executes."""

import numpy as np
import pytest

from core import robots
from core.control.grasp_place import immediate
from core.control.run_estimate import LegTimer, executing_plan, plan_seconds, remaining_seconds
from core.control.sim import SoftArmSim
from core.control.sim_loop import SimLoop
from core.control.stack import ControlStack
from core.planning.grasp import plan_grasp

FACTOR = 1.3  # the stated bound: estimate / simulated duration within [1/FACTOR, FACTOR]
R = 0.0165


@pytest.fixture(scope="module")
def arm():
    return robots.load("soft-arm")


def _run(arm, xy):
    """One grasp-and-place of an object at ``xy`` on the simulated clock: the duration, and
    (time, remaining estimate, plan) at every tick with a plan."""
    sim = SoftArmSim(arm, seed=1)
    sim.place_object(*xy, R)
    stack = ControlStack(arm, 0.01, immediate(
        lambda req: plan_grasp(arm, req.kappa, req.center, req.radius)))
    loop = SimLoop(sim, stack, 0.01)
    loop.run(0.05)
    loop.arm()
    loop.run(0.5)
    start_kappa = sim.kappa.copy()
    timer = LegTimer(arm)
    loop.start_task()
    t0, seen = loop.t, []
    while loop.t - t0 < 120.0:
        c = loop.tick()
        plan = executing_plan(stack.machine)
        if plan is not None:
            now = c.kappa_meas if c.kappa_meas is not None else c.kappa_ref  # markers occluded
            seen.append((loop.t - t0, remaining_seconds(arm, timer, c.phase, now, plan,
                                                        c.waypoint), plan, stack.machine.plan))
        if c.phase in ("released", "stopped"):
            break
    assert c.phase == "released"
    return loop.t - t0, start_kappa, seen


@pytest.mark.parametrize("xy", [(-0.22, 0.20), (-0.08, 0.33)])
def test_the_estimates_are_within_the_stated_factor_of_the_simulated_run(arm, xy):
    duration, start_kappa, seen = _run(arm, xy)
    timer = LegTimer(arm)
    _, first_left, plan, machine_plan = seen[0]
    # Before Execute: the whole task from where the arm was, the controller planning itself.
    before = plan_seconds(arm, timer, start_kappa, plan.kappas, plan.carry, planned=False)
    assert 1 / FACTOR <= before / duration <= FACTOR, (before, duration)
    # While running: elapsed + remaining at every 5 s is the run's duration within the factor.
    for t, left, _, _ in seen[::500]:
        assert 1 / FACTOR <= (t + left) / duration <= FACTOR, (t, left, duration)
    # The remaining time only runs out when the arm is done.
    assert first_left > 0.5 * duration and seen[-1][1] <= arm.state_machine.release_time_s
    # The published plan is the machine's own (waypoints and palm points, as planned).
    np.testing.assert_array_equal(plan.kappas, np.asarray(machine_plan.kappas))
    np.testing.assert_array_equal(plan.palms, np.asarray(machine_plan.palm_poses))
    assert plan.center == pytest.approx(xy, abs=0.01)
    np.testing.assert_allclose(plan.carry[-1], arm.bin.kappa_for("left"), atol=1e-12)


def test_a_leg_takes_what_a_jerk_limited_rest_to_rest_motion_takes(arm):
    """Closed form: a long move of one curvature under velocity v, acceleration a and jerk j
    (reaching both limits) takes d / v + v / a + a / j."""
    timer = LegTimer(arm)
    lim = arm.trajectory
    v, a, j = lim.max_velocity[0], lim.max_acceleration[0], lim.max_jerk[0]
    d = 6.0
    q = np.zeros(arm.n_segments)
    b = q.copy()
    b[0] = d
    assert timer.leg(q, b) == pytest.approx(d / v + v / a + a / j, rel=1e-6)
    assert timer.leg(q, q) == 0.0
    assert remaining_seconds(arm, timer, "released", q, None) == 0.0
    assert remaining_seconds(arm, timer, "settling", q, None) is None
