"""Grasp planner (Algorithm 1) against the paper: constraints, radii, clearance, optimality,
refusals and the command line. References are computed independently with
core.kinematics.planar, dense backbone sampling and scipy."""

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import minimize

from core import robots
from core.kinematics import planar
from core.planning.grasp import GraspPlanner, GraspRefused, plan_grasp

ARM = robots.load("soft-arm")
L = ARM.lengths
G = ARM.gripper
KMAX = ARM.kappa_max
TOL = ARM.constraint_tolerance          # 2e-3, the paper's
REPO = Path(__file__).resolve().parents[2]
STRAIGHT = np.zeros(6)

# Left-quadrant objects of the paper's sizes (2-5 cm diameter), arm straight.
OBJECTS = [(-0.20, 0.20, 0.0165), (-0.10, 0.10, 0.010), (-0.30, 0.05, 0.025),
           (-0.25, 0.30, 0.0125), (-0.05, 0.30, 0.020), (-0.15, 0.35, 0.0165)]
# Curled starts that make the planner re-solve with clearance constraints / insert waypoints.
HARD = [([-6.3, 2.5, 8.0, 1.2, 3.5, -3.0], (-0.024, 0.045), 0.0165),
        ([4.2, 4.8, -0.8, -6.6, -5.0, 2.1], (-0.137, 0.316), 0.0165),
        ([-0.1, 7.6, -3.2, -2.2, -3.8, 2.3], (-0.106, 0.346), 0.0165)]


def palm(kappa):
    """Palm point w_t = tip + R(theta) w_off and heading, from the kinematics module."""
    tip = planar.forward_kinematics(kappa, L, ARM.base_pose)[-1]
    return planar.point_in_frame(tip, G.w_off), tip[2]


def body_gap(kappas, center, radius, per_segment=48):
    """Arm-body-to-disk gap by dense backbone sampling (gripper excluded), shape kappas[:-1]."""
    bb = planar.sample_backbone(kappas, L, per_segment, ARM.base_pose)
    d = np.hypot(bb[..., 0] - center[0], bb[..., 1] - center[1]).min(axis=-1)
    return d - ARM.half_width - radius


def algorithm1_radii(kappa_meas, center, radius, delta_d):
    w_t, _ = palm(kappa_meas)
    d1 = math.dist(center, w_t)
    d2 = d1 - radius - G.g_off
    n = max(1, math.floor(d2 / delta_d))
    return d1, d2, n, np.array([d1 - i * d2 / n for i in range(1, n + 1)])


ALL = [(STRAIGHT, o[:2], o[2]) for o in OBJECTS] + [(np.array(k), c, r) for k, c, r in HARD]


@pytest.fixture(scope="module")
def plans():
    return [plan_grasp(ARM, k, c, r) for k, c, r in ALL]


def test_plans_succeed_and_expose_the_public_arrays(plans):
    for plan in plans:
        assert plan.success, plan.summary()
        n = plan.n
        assert plan.radii.shape == (n,) and plan.phis.shape == (n,)
        assert plan.kappas.shape == (n, 6) and plan.palm_poses.shape == (n, 3)
        assert plan.circles.shape == (n, 3) and plan.clearance.shape == (n,)
        assert set(plan.status) == {"ok"}


def test_every_waypoint_satisfies_algorithm1s_constraints(plans):
    for plan in plans:
        cx, cy = plan.center
        for ra, phi, kappa, pose in zip(plan.radii, plan.phis, plan.kappas, plan.palm_poses):
            w, heading = palm(kappa)
            target = np.array([cx + ra * math.cos(phi), cy + ra * math.sin(phi)])
            assert np.abs(w - target).max() <= TOL / 1000       # converged far below 2e-3
            assert abs(math.remainder(heading - (phi + math.pi / 2), 2 * math.pi)) <= 1e-9
            assert np.all(np.abs(kappa) <= KMAX + 1e-12)
            np.testing.assert_allclose(pose, [w[0], w[1], heading], atol=1e-12)
            # Counter-clockwise tangent: the object centre is on the gripper's left.
            left = np.array([-math.sin(heading), math.cos(heading)])
            assert np.dot(np.array([cx, cy]) - w, left) == pytest.approx(ra, abs=1e-7)


def test_radii_follow_algorithm1s_formula(plans):
    for (km, c, r), plan in zip(ALL, plans):
        d1, d2, n, radii = algorithm1_radii(km, c, r, ARM.delta_d)
        assert plan.d1 == pytest.approx(d1, abs=1e-12) and plan.num_moves == n
        np.testing.assert_allclose(plan.radii[~plan.inserted], radii, atol=1e-12)
        assert radii[-1] == pytest.approx(r + G.g_off, abs=1e-12)
        # Inserted waypoints lie strictly between their neighbours' circles.
        full = np.r_[d1, plan.radii]
        assert np.all(np.diff(full) < 0)


def test_delta_d_changes_the_number_of_moves():
    plan = plan_grasp(ARM, STRAIGHT, (-0.2, 0.2), 0.0165, delta_d=0.02)
    d1, d2, n, radii = algorithm1_radii(STRAIGHT, (-0.2, 0.2), 0.0165, 0.02)
    assert plan.num_moves == n == math.floor(d2 / 0.02)
    np.testing.assert_allclose(plan.radii[~plan.inserted], radii, atol=1e-12)


def test_arm_body_stays_out_of_the_disk_at_waypoints_and_along_kappa_lines(plans):
    tau = np.linspace(0.0, 1.0, 201)
    for plan in plans:
        gaps = body_gap(plan.kappas, plan.center, plan.radius)
        assert np.all(gaps >= ARM.planner.clearance_margin - 1e-6)
        # Reported clearance is the exact value (dense sampling is an upper bound on it).
        assert np.all(plan.clearance <= gaps + 1e-12)
        assert np.all(plan.clearance >= gaps - 2e-4)
        chain = np.vstack([plan.kappa_meas, plan.kappas])
        lines = chain[:-1, None, :] + tau[:, None] * (chain[1:] - chain[:-1])[:, None, :]
        dense = body_gap(lines, plan.center, plan.radius).min(axis=1)
        assert np.all(dense >= 0.0)
        assert np.all(plan.path_clearance <= dense + 1e-12)     # a true lower bound


def test_hard_starts_exercise_constrained_resolves_and_inserted_waypoints(plans):
    hard = plans[len(OBJECTS):]
    assert hard[0].clearance_constrained.any()
    assert hard[1].inserted.any() and hard[2].inserted.any()


def _slsqp(kappa_meas, center, ra, z0, jac=True):
    """findOptimalConfig in the paper's variables (kappa, phi) with scipy SLSQP."""
    cx, cy = center

    def cons(z):
        w, th = palm(z[:6])
        return np.array([w[0] - cx - ra * math.cos(z[6]), w[1] - cy - ra * math.sin(z[6]),
                         th - z[6] - math.pi / 2])

    def cons_jac(z):
        _, jac_w = planar.tip_jacobian(z[:6], L, offset=G.w_off, base_pose=ARM.base_pose)
        Jc = np.zeros((3, 7))
        Jc[:, :6] = jac_w
        Jc[:, 6] = [ra * math.sin(z[6]), -ra * math.cos(z[6]), -1.0]
        return Jc

    res = minimize(lambda z: float(np.sum((z[:6] - kappa_meas) ** 2)), z0,
                   jac=lambda z: np.r_[2 * (z[:6] - kappa_meas), 0.0], method="SLSQP",
                   bounds=[(-KMAX, KMAX)] * 6 + [(None, None)],
                   constraints=[{"type": "eq", "fun": cons, "jac": cons_jac if jac else None}],
                   options={"ftol": 1e-12, "maxiter": 500})
    return res, np.abs(cons(res.x)).max()


def test_waypoints_are_local_minima_compared_with_scipy_slsqp(plans):
    for (km, c, r), plan in zip(ALL[:len(OBJECTS)], plans[:len(OBJECTS)]):
        cost = np.sum((plan.kappas - km) ** 2, axis=1)
        np.testing.assert_allclose(plan.cost, cost, rtol=1e-12)
        for i in range(plan.n):
            z = np.r_[plan.kappas[i], plan.palm_poses[i, 2] - math.pi / 2]
            # SLSQP started at our solution finds nothing better nearby ...
            res, viol = _slsqp(km, c, plan.radii[i], z)
            assert viol < 1e-6
            assert res.fun >= cost[i] * (1 - 1e-6) - 1e-9
            # ... and from the same warm start as ours (the previous waypoint) reaches the same
            # cost, unless it stops at a worse point.
            if i:
                z0 = np.r_[plan.kappas[i - 1], plan.palm_poses[i - 1, 2] - math.pi / 2]
                res, viol = _slsqp(km, c, plan.radii[i], z0)
                if res.success and viol < 1e-6:
                    assert cost[i] <= res.fun * (1 + 1e-5) + 1e-9


@pytest.mark.parametrize("center, radius, reason, words", [
    ((0.6, 0.6), 0.02, "out_of_reach", "out of reach"),
    ((-0.05, -0.38), 0.0165, "out_of_reach", "out of reach"),
    ((0.01, 0.02), 0.0165, "on_base", "base"),
    ((-0.2, 0.2), 0.05, "too_large", "too large"),
    ((0.0, 0.2), 0.0165, "on_arm", "overlaps the arm"),
    ((-0.02, 0.42), 0.0165, "on_gripper", "overlaps the gripper"),
    ((-0.2, 0.2), -0.01, "bad_input", "positive"),
    ((float("nan"), 0.2), 0.01, "bad_input", "finite"),
])
def test_refusals_say_why_in_plain_words(center, radius, reason, words):
    with pytest.raises(GraspRefused) as exc:
        plan_grasp(ARM, STRAIGHT, center, radius)
    assert isinstance(exc.value, ValueError)
    assert exc.value.reason == reason
    assert words in str(exc.value)


def _gripper_gap(kappa, center, radius, half_width):
    """Gap (m) between a disk and the straight gripper (a segment from the tip along its heading,
    widened by ``half_width``), from the kinematics module and plain geometry."""
    tip = planar.forward_kinematics(kappa, L, ARM.base_pose)[-1]
    root, heading = np.asarray(tip[:2]), np.array([math.cos(tip[2]), math.sin(tip[2])])
    along = float(np.clip((np.asarray(center) - root) @ heading, 0.0, G.length))
    return float(np.hypot(*(np.asarray(center) - root - along * heading))) - half_width - radius


@pytest.mark.parametrize("center", [(-0.20, 0.20), (-0.08, 0.33), (0.15, 0.25)])
def test_an_object_the_fingers_pushed_is_planned_for_deeper_overlap_refused(center):
    # An approach that brushes the object pushes it (the simulated plant: it ends against the
    # 8 mm fingers, which the 12 mm drawn gripper would overlap by 4 mm); the state machine
    # re-plans from there and must get a plan, not a refusal.
    from core.control.sim import SoftArmSim
    from core.planning.sides import plan_grasp_sided
    r, fingers = 0.0165, ARM.sim.gripper.finger_half_width
    assert G.half_width - fingers == pytest.approx(0.004)
    at = plan_grasp_sided(ARM, STRAIGHT, center, r).kappas[-1]  # the gripper around the object
    gap = _gripper_gap(at, center, r, fingers)
    assert gap > 0.004
    tip = planar.forward_kinematics(at, L, ARM.base_pose)[-1]
    heading = np.array([math.cos(tip[2]), math.sin(tip[2])])
    rel = np.asarray(center) - tip[:2]
    normal = rel - (rel @ heading) * heading
    normal /= np.hypot(*normal)
    sim = SoftArmSim(ARM, kappa0=at)
    sim.place_object(*(np.asarray(center) - (gap + 0.006) * normal), r)  # pushed out at once
    pushed = sim.obj.xy.copy()
    assert _gripper_gap(at, pushed, r, fingers) == pytest.approx(0.0, abs=3e-4)  # touching
    assert _gripper_gap(at, pushed, r, G.half_width) < -0.0035
    for xy in (pushed, pushed - 0.0009 * normal):  # touching, and marker noise further in
        plan = plan_grasp_sided(ARM, at, xy, r)
        side = 1.0 if plan.side == "left" else -1.0
        end_tip = planar.forward_kinematics(plan.kappas[-1], L, ARM.base_pose)[-1]
        w = planar.point_in_frame(end_tip, (G.w_off_along, side * G.g_off))
        assert np.hypot(*(np.asarray(w) - xy)) == pytest.approx(r + G.g_off, abs=TOL)
        assert _gripper_gap(plan.kappas[-1], xy, r, G.half_width) > 0.0
    with pytest.raises(GraspRefused) as exc:
        plan_grasp_sided(ARM, at, pushed - 0.003 * normal, r)
    assert exc.value.reason == "on_gripper" and "by 3.0 mm" in str(exc.value)


def test_refused_object_within_the_reach_bound_has_no_final_configuration():
    # Behind the base: inside the crude reach bound but no arm shape gets the gripper around it.
    with pytest.raises(GraspRefused) as exc:
        plan_grasp(ARM, STRAIGHT, (-0.25, -0.25), 0.0165)
    assert exc.value.reason == "out_of_reach" and "curvature limit" in str(exc.value)


def test_bad_inputs_are_refused():
    for km in (np.zeros(5), np.full(6, np.nan)):
        with pytest.raises(GraspRefused):
            plan_grasp(ARM, km, (-0.2, 0.2), 0.02)
    with pytest.raises(GraspRefused):
        plan_grasp(ARM, STRAIGHT, (-0.2, 0.2), 0.02, delta_d=0.0)
    with pytest.raises(GraspRefused):
        plan_grasp(ARM, STRAIGHT, (-0.2, 0.2), 0.02, weights=[1, 1, 1, 1, 1, -1])


def test_failed_radius_is_reported_with_a_reason():
    # Under the base: the final circle is reachable but Algorithm 1's larger circles are not.
    plan = GraspPlanner(ARM).plan(STRAIGHT, (-0.05, -0.05), 0.0165)
    assert not plan.success
    f = plan.failures[0]
    assert f.reason == "curvature_limit" and 1 <= f.index < plan.num_moves
    assert plan.status[list(plan.radii).index(f.radius)] == "curvature_limit"
    assert "FAILED" in plan.summary()


def test_sweep_through_the_object_is_reported_as_a_clearance_failure():
    km = np.array([6.28, 7.3, -5.28, -5.54, -1.08, 1.56])
    plan = plan_grasp(ARM, km, (-0.004, 0.385), 0.0248)
    assert not plan.success
    assert plan.failures[0].reason == "clearance" and "mm into the object" in plan.failures[0].detail


def test_weights_change_the_solution_as_the_cost_says():
    base = plan_grasp(ARM, STRAIGHT, (-0.2, 0.2), 0.0165)
    w = np.array([10.0, 10.0, 1.0, 1.0, 1.0, 1.0])
    heavy = plan_grasp(ARM, STRAIGHT, (-0.2, 0.2), 0.0165, weights=w)
    assert heavy.success
    # Heavier root weights move bending away from the root segments.
    assert np.abs(heavy.kappas[-1, :2]).sum() < np.abs(base.kappas[-1, :2]).sum()
    np.testing.assert_allclose(heavy.cost, (w * heavy.kappas ** 2).sum(axis=1), rtol=1e-12)


def test_json_round_trip():
    plan = plan_grasp(ARM, STRAIGHT, (-0.2, 0.2), 0.0165)
    data = json.loads(json.dumps(plan.to_dict()))
    np.testing.assert_allclose(data["kappas"], plan.kappas)
    assert data["success"] is True and len(data["circles"]) == plan.n


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "core.planning.grasp", *args], cwd=REPO,
                          capture_output=True, text=True, timeout=60)


def test_cli_prints_the_plan_and_exits_2_on_refusal():
    ok = _cli("--object", "-0.2", "0.2", "0.0165", "--json")
    assert ok.returncode == 0, ok.stderr
    data = json.loads(ok.stdout)
    assert data["num_moves"] == len(data["radii"]) and data["success"]
    table = _cli("--object", "-0.2", "0.2", "0.0165")
    assert table.returncode == 0 and "r_a" in table.stdout and "waypoints" in table.stdout
    far = _cli("--object", "0.6", "0.6", "0.02")
    assert far.returncode == 2 and "out of reach" in far.stderr and far.stdout == ""
