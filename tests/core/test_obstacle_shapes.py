"""The grasp-shape search around obstacles (#17.1): a refusal says which case it is -- no grasp
shape keeps the clearance (an obstacle ring round the object, checked geometrically), or clear
grasp shapes exist (checked by dense forward kinematics) but no clear way to them was found --
and the search is deterministic given its seed."""

import math
import time

import numpy as np
import pytest

from core import robots
from core.kinematics import planar
from core.planning.grasp import GraspPlanner, Obstacle
from core.planning.grasp_shapes import grasp_shapes
from core.planning.obstacle_planning import ObstacleRefused, _check, plan_around
from tests.core.test_obstacles import dense_gap, lines

ARM = robots.load("soft-arm")
PLANNER = GraspPlanner(ARM)
STRAIGHT = np.zeros(6)
R_OBJECT = 0.0165
CLEARANCE = 0.010
# Blocked spots of benchmarks/bench_obstacle_planner.py: one main's planner refused that the
# grasp-shape search plans, one both refuse.
SPOT = ((-0.28, 0.28), Obstacle("Obstacle 1", -0.098, 0.28, 0.015))
REFUSED = ((-0.28, 0.20), Obstacle("Obstacle 1", -0.098, 0.20, 0.015))
RING_CENTER = (-0.20, 0.20)


def ring() -> tuple[Obstacle, ...]:
    """Eight 10 mm posts round the object, on the circle the gripper's root must be on."""
    g = ARM.gripper
    rho = math.hypot(g.w_off_along, 2.0 * g.g_off + R_OBJECT)
    return tuple(Obstacle(f"Post {k + 1}", RING_CENTER[0] + rho * math.cos(k * math.pi / 4),
                          RING_CENTER[1] + rho * math.sin(k * math.pi / 4), 0.010)
                 for k in range(8))


def test_no_grasp_shape_clears_the_ring_checked_geometrically():
    # Any grasp puts the object centre at the offset (w_along, 2 g_off + r) of the tip frame:
    # the arm's tip is on a circle of that radius round the object. Everywhere on it the arm
    # body (half-width round the tip) is closer than the clearance to a post.
    g = ARM.gripper
    rho = math.hypot(g.w_off_along, 2.0 * g.g_off + R_OBJECT)
    c = complex(*RING_CENTER)
    tips = c + rho * np.exp(1j * np.linspace(0.0, 2.0 * math.pi, 3601))
    gaps = np.min([np.abs(tips - o.center) - o.r - ARM.half_width for o in ring()], axis=0)
    assert gaps.max() < CLEARANCE


def test_a_ring_round_the_object_is_refused_as_no_grasp_shape():
    posts = ring()
    with pytest.raises(ObstacleRefused) as exc:
        plan_around(PLANNER, STRAIGHT, RING_CENTER, R_OBJECT, None, None, posts, CLEARANCE)
    msg = str(exc.value)
    assert exc.value.obstacle in {o.name for o in posts}
    assert msg.startswith(f"{exc.value.obstacle} is in the way: no grasp shape found keeps the "
                          f"arm and gripper 10 mm clear of it"), msg
    assert exc.value.clearance == CLEARANCE


def test_refusal_says_clear_grasp_shapes_exist_and_they_do():
    center, o = REFUSED
    with pytest.raises(ObstacleRefused) as exc:
        plan_around(PLANNER, STRAIGHT, center, R_OBJECT, None, None, (o,), CLEARANCE)
    msg = str(exc.value)
    assert msg.startswith("Obstacle 1 is in the way: grasp shapes 10 mm clear of it exist ("), msg
    assert "but no clear way to them was found in" in msg
    assert (exc.value.obstacle, exc.value.clearance) == ("Obstacle 1", CLEARANCE)
    # They do: sampled grasp shapes, checked by dense forward kinematics and the palm pose.
    found = _shapes(center, o, seed=0)
    assert len(found.shapes) >= 1
    assert dense_gap(found.shapes, o).min() >= CLEARANCE - 1e-9
    g = ARM.gripper
    for q in found.shapes:
        bb = planar.sample_backbone(q[None], ARM.lengths, 8, ARM.base_pose)[0, -1]
        t = complex(bb[0], bb[1])
        h = np.exp(1j * bb[2])
        assert abs(t + h * complex(g.w_off_along, 2 * g.g_off + R_OBJECT) - complex(*center)) \
            < 1e-6


def test_the_shape_search_is_deterministic_given_its_seed():
    center, o = SPOT
    a, b, c = _shapes(center, o, 0), _shapes(center, o, 0), _shapes(center, o, 7)
    np.testing.assert_array_equal(a.shapes, b.shapes)
    assert a.shapes.shape != c.shapes.shape or np.any(a.shapes != c.shapes)


def _shapes(center, o, seed):
    setup = _check(PLANNER, STRAIGHT, center, R_OBJECT, (o,), CLEARANCE)
    return grasp_shapes(PLANNER, setup, complex(*center), R_OBJECT, 6, 24, seed,
                        time.thread_time() + 600.0)


@pytest.mark.slow(25)  # s on 2 busy cores (2026-12-05)
def test_a_spot_main_refused_is_planned_clear_along_every_line():
    center, o = SPOT
    with pytest.raises(ObstacleRefused, match="Obstacle 1 is in the way: no approach found"):
        plan_around(PLANNER, STRAIGHT, center, R_OBJECT, None, None, (o,), CLEARANCE,
                    shape_search=False)
    plan = plan_around(PLANNER, STRAIGHT, center, R_OBJECT, None, None, (o,), CLEARANCE)
    assert plan.success
    gaps = dense_gap(lines(plan), o)           # arm body and gripper, every line, densely
    assert gaps.min() >= CLEARANCE - 1e-9, gaps.min()
    # It ends with the grasp: the palm on the final circle round the object.
    assert plan.radii[-1] == pytest.approx(R_OBJECT + ARM.gripper.g_off, abs=1e-6)
    again = plan_around(PLANNER, STRAIGHT, center, R_OBJECT, None, None, (o,), CLEARANCE)
    np.testing.assert_array_equal(again.kappas, plan.kappas)   # deterministic
