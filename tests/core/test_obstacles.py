"""Obstacles for the planar arm's grasp planner (#17.1): the whole arm, gripper included, keeps
the set clearance from every obstacle at and between waypoints, and a request the obstacles
make impossible is refused naming the obstacle and by how much. References are independent:
dense sampling of core.kinematics.planar's forward kinematics plus the straight gripper."""

import math

import numpy as np
import pytest

from core import robots
from core.kinematics import planar
from core.planning.arm_model import ArmModel
from core.planning.grasp import GraspPlanner, GraspRefused, Obstacle, plan_grasp
from core.planning.obstacles import (GripperShape, ObstacleConstraints,
                                     certify_obstacle_lines, obstacle_clearance)

ARM = robots.load("soft-arm")
MODEL = ArmModel.from_robot(ARM)
GRIP = GripperShape.from_robot(ARM)
STRAIGHT = np.zeros(6)
OBJECT = ((-0.20, 0.20), 0.0165)
# Between the straight arm (x = 0) and the object, in the way of the plain plan's sweep.
BETWEEN = Obstacle("Obstacle 1", -0.07, 0.21, 0.015)
CLEARANCE = 0.010


def dense_gap(kappas, obstacle, per_segment=64, grip_samples=65):
    """Gap between the arm (backbone +- half-width, straight gripper +- its half-width) and
    the obstacle disk, by dense sampling of the forward kinematics; shape kappas[:-1]."""
    bb = planar.sample_backbone(kappas, ARM.lengths, per_segment, ARM.base_pose)
    d_body = np.hypot(bb[..., 0] - obstacle.x, bb[..., 1] - obstacle.y).min(axis=-1)
    tip = bb[..., -1, :]
    s = np.linspace(0.0, ARM.gripper.length, grip_samples)
    gx = tip[..., 0:1] + s * np.cos(tip[..., 2:3])
    gy = tip[..., 1:2] + s * np.sin(tip[..., 2:3])
    d_grip = np.hypot(gx - obstacle.x, gy - obstacle.y).min(axis=-1)
    return np.minimum(d_body - ARM.half_width, d_grip - ARM.gripper.half_width) - obstacle.r


def lines(plan, samples=401):
    chain = np.vstack([plan.kappa_meas, plan.kappas])
    tau = np.linspace(0.0, 1.0, samples)
    return chain[:-1, None, :] + tau[:, None] * (chain[1:] - chain[:-1])[:, None, :]


def test_exact_clearance_matches_dense_sampling_of_the_kinematics():
    rng = np.random.default_rng(3)
    kappas = rng.uniform(-ARM.kappa_max, ARM.kappa_max, (300, 6))
    obstacles = [Obstacle("A", -0.1, 0.25, 0.02), Obstacle("B", 0.12, 0.3, 0.03)]
    exact = obstacle_clearance(MODEL, kappas, obstacles, GRIP)
    for j, o in enumerate(obstacles):
        dense = dense_gap(kappas, o, per_segment=400, grip_samples=2001)
        assert np.all(exact[:, j] <= dense + 1e-12)             # exact <= any sample
        assert np.all(exact[:, j] >= dense - 1e-4)


def test_line_certificate_is_a_lower_bound_along_straight_kappa_lines():
    rng = np.random.default_rng(5)
    a = rng.uniform(-8, 8, (24, 6))
    b = rng.uniform(-8, 8, (24, 6))
    o = Obstacle("A", -0.08, 0.22, 0.02)
    cert = certify_obstacle_lines(MODEL, a, b, [o], GRIP, required=0.01)
    tau = np.linspace(0.0, 1.0, 401)
    dense = dense_gap(a[:, None] + tau[:, None] * (b - a)[:, None], o).min(axis=1)
    assert np.all(cert.lower_bound[:, 0] <= dense + 1e-12)
    # ... and a useful one where it matters: every line clear by 1 mm is certified clear.
    clear = dense >= 0.011
    assert clear.any() and (~clear).any()
    assert np.all(cert.lower_bound[clear, 0] >= 0.01)


def test_solver_rows_match_the_batched_distances_and_their_derivatives():
    rows = ObstacleConstraints.build(MODEL, [Obstacle("A", -0.1, 0.2, 0.02),
                                             Obstacle("B", 0.05, 0.42, 0.03)], GRIP, 0.01)
    rng = np.random.default_rng(1)
    for _ in range(20):
        x = rng.uniform(-16, 16, 6).tolist()
        h, aux = rows.evaluate(MODEL, x)
        dist, _ = MODEL.arc_distances(np.broadcast_to(np.array(x), (2, 6)),
                                      np.array(rows.centers))
        body = h.reshape(2, 7)[:, :6]
        want = dist - np.array(rows.rho_body)[:, None]
        at_start = aux[0] == 0.0         # the previous segment's end (or the base): inactive
        np.testing.assert_allclose(body[~at_start], want[~at_start], atol=1e-12)
        assert np.all(body[at_start] >= want[at_start] + 1.0)
        G = np.array(rows.jacobian(MODEL, x, aux))
        fd = np.zeros_like(G)
        for j in range(6):
            xp, xm = list(x), list(x)
            xp[j] += 1e-6
            xm[j] -= 1e-6
            fd[:, j] = (rows.evaluate(MODEL, xp)[0] - rows.evaluate(MODEL, xm)[0]) / 2e-6
        np.testing.assert_allclose(G, fd, atol=1e-6)


def test_plan_around_an_obstacle_between_the_arm_and_the_object_keeps_the_clearance():
    plain = plan_grasp(ARM, STRAIGHT, *OBJECT)
    assert dense_gap(lines(plain), BETWEEN).min() < CLEARANCE   # the plain plan is in the way
    plan = plan_grasp(ARM, STRAIGHT, *OBJECT, obstacles=[BETWEEN], clearance=CLEARANCE)
    assert plan.success, plan.summary()
    assert plan.obstacles == (BETWEEN,) and plan.obstacle_margin == CLEARANCE
    # Certified between waypoints ...
    assert np.all(plan.obstacle_path_clearance >= CLEARANCE)
    # ... and checked independently: every arm and gripper point along every straight line
    # in kappa the curvature controller follows (from the arm's shape now) keeps clear.
    dense = dense_gap(lines(plan), BETWEEN).min(axis=1)
    assert np.all(dense >= CLEARANCE - 1e-9)
    assert np.all(plan.obstacle_path_clearance <= dense + 1e-12)  # a true lower bound
    np.testing.assert_allclose(plan.obstacle_clearance, dense_gap(plan.kappas, BETWEEN),
                               atol=1e-4)
    # Still Algorithm 1 for the object: last waypoint on the final circle, object clear.
    assert plan.radii[-1] == pytest.approx(OBJECT[1] + ARM.gripper.g_off, abs=1e-12)
    assert np.all(plan.path_clearance >= 0.0)
    d = plan.to_dict()
    assert d["obstacles"] == [{"name": "Obstacle 1", "x": -0.07, "y": 0.21, "r": 0.015}]


def test_an_obstacle_out_of_the_way_changes_nothing():
    far = Obstacle("Far", 0.3, 0.05, 0.02)
    plain = plan_grasp(ARM, STRAIGHT, *OBJECT)
    plan = plan_grasp(ARM, STRAIGHT, *OBJECT, obstacles=[far], clearance=CLEARANCE)
    np.testing.assert_array_equal(plan.kappas, plain.kappas)
    assert np.all(plan.obstacle_path_clearance >= CLEARANCE)


def test_an_object_the_obstacles_make_unreachable_is_refused_naming_the_obstacle():
    wall = Obstacle("Wall", -0.10, 0.30, 0.02)
    cup = Obstacle("Cup", 0.30, 0.05, 0.02)              # out of the way
    planner = GraspPlanner(ARM)
    plain = planner.plan(STRAIGHT, *OBJECT)
    with pytest.raises(GraspRefused) as info:
        planner.plan(STRAIGHT, *OBJECT, obstacles=[cup, wall], clearance=CLEARANCE)
    exc = info.value
    assert exc.reason == "obstacle" and exc.obstacle == "Wall"
    assert "Wall" in str(exc) and "Cup" not in str(exc)
    # "By how much": the gap of the direct approach, checked by dense sampling.
    gap = dense_gap(lines(plain), wall).min()
    assert exc.gap == pytest.approx(gap, abs=1e-3)
    assert f"{-gap * 1e3:.0f} mm" in str(exc)


@pytest.mark.parametrize("obstacle, clearance, words", [
    (Obstacle("O", math.nan, 0.2, 0.02), 0.01, "finite"),
    (Obstacle("O", -0.1, 0.2, -0.02), 0.01, "positive"),
    (Obstacle("O", 0.0, 0.01, 0.02), 0.01, "on the arm's base"),
    (Obstacle("O", -0.1, 0.2, 0.02), -0.01, "clearance"),
    (Obstacle("O", -0.1, 0.2, 0.02), math.nan, "clearance"),
])
def test_bad_obstacles_are_refused_with_a_clear_message(obstacle, clearance, words):
    with pytest.raises(GraspRefused) as info:
        plan_grasp(ARM, STRAIGHT, *OBJECT, obstacles=[obstacle], clearance=clearance)
    assert info.value.reason == "bad_input" and words in str(info.value)


def test_object_on_an_obstacle_and_arm_inside_the_clearance_are_refused():
    with pytest.raises(GraspRefused, match="overlaps Pillar") as info:
        plan_grasp(ARM, STRAIGHT, *OBJECT, obstacles=[Obstacle("Pillar", -0.18, 0.2, 0.02)],
                   clearance=CLEARANCE)
    assert info.value.reason == "obstacle"
    near = Obstacle("Post", 0.035, 0.2, 0.015)     # 7.5 mm from the straight arm's side
    with pytest.raises(GraspRefused, match="too close to Post now: it is 8 mm") as info:
        plan_grasp(ARM, STRAIGHT, *OBJECT, obstacles=[near], clearance=CLEARANCE)
    assert info.value.obstacle == "Post"


def test_command_line_plans_around_obstacles_and_refuses_naming_them():
    import subprocess
    import sys
    from pathlib import Path

    repo = Path(__file__).resolve().parents[2]
    run = lambda *a: subprocess.run(  # noqa: E731
        [sys.executable, "-m", "core.planning.grasp", "--object", "-0.2", "0.2", "0.0165", *a],
        cwd=repo, capture_output=True, text=True, timeout=120)
    ok = run("--obstacle", "-0.07", "0.21", "0.015", "--clearance", "0.01")
    assert ok.returncode == 0, ok.stderr
    import re
    m = re.search(r"Obstacles \(Obstacle 1\): the arm and gripper keep >= ([\d.]+) mm", ok.stdout)
    assert m and float(m.group(1)) >= 10.0, ok.stdout
    bad = run("--obstacle", "0.3", "0.05", "0.02", "--obstacle", "-0.1", "0.3", "0.02")
    assert bad.returncode == 2
    assert bad.stderr.startswith("refused (obstacle): Obstacle 2 is in the way")


def test_first_overlap_is_the_first_disk_closer_than_the_radii_and_touching_is_clear():
    from core.planning.obstacles import first_overlap

    a, b = Obstacle("A", 0.10, 0.0, 0.02), Obstacle("B", 0.0, 0.05, 0.03)
    assert first_overlap(0.0, 0.0, 0.02, [a, b]) is None   # B at 50 mm = 30 + 20: touching
    hit = first_overlap(0.0, 0.0, 0.025, [b, a])          # B 5 mm in; A 55 mm off
    assert hit is not None and hit[0] is b and hit[1] == pytest.approx(-0.005)
    hit = first_overlap(0.09, 0.03, 0.02, [a, b])         # both overlap: the first listed
    assert hit is not None and hit[0] is a
    assert hit[1] == pytest.approx(math.hypot(0.01, 0.03) - 0.04)
