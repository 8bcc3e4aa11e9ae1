"""Tip IK of the extensible arm (eq. 4-6): against forward kinematics, the rack and bending limits,
closed-form distances to unreachable targets and an independent constrained optimiser."""

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.optimize import minimize

from core import robots
from core.kinematics import delta as dk
from core.kinematics.delta_ik import TipIKResult, solve_tip_ik
from core.robot_schema import tomllib
from core.robot_sections import IKSettings

ARM = robots.load("extensible")
LO, HI = ARM.rack_min, ARM.rack_max
TOL = 1e-3
FREE = dataclasses.replace(ARM, theta_max=2 * math.pi)  # racks only (up to a full turn)


def bends(delta):
    """theta = |(dx, dy)| / d per segment, computed here."""
    delta = np.asarray(delta)
    return np.sqrt(delta[..., 0] ** 2 + delta[..., 1] ** 2) / ARM.rack_radius


def random_reachable(rng, count):
    """Targets reachable by construction: tips of random rack lengths within the rack limits
    whose bends are within theta_max (rejection sampling)."""
    out = np.zeros((0, ARM.n_segments, 3))
    while len(out) < count:
        lengths = rng.uniform(LO, HI, (20 * count, ARM.n_segments, 3))
        ok = (bends(dk.delta_from_actuators(lengths, ARM.phi, ARM.L0)) <= ARM.theta_max).all(1)
        out = np.concatenate([out, lengths[ok]])
    lengths = out[:count]
    deltas = dk.delta_from_actuators(lengths, ARM.phi, ARM.L0)
    return lengths, dk.tip_position(ARM, deltas)


def assert_consistent(res, target):
    """Invariants of every result: limits, delta <-> lengths, error and tip by FK."""
    assert isinstance(res, TipIKResult)
    assert res.delta.shape == (ARM.n_segments, 3) and res.lengths.shape == (ARM.n_segments, 3)
    assert np.all(res.lengths >= LO) and np.all(res.lengths <= HI)
    assert np.all(bends(res.delta) <= ARM.theta_max)
    np.testing.assert_allclose(dk.robot_rack_lengths(ARM, res.delta), res.lengths, atol=1e-12)
    tip = dk.tip_position(ARM, res.delta)
    np.testing.assert_allclose(res.tip, tip, atol=1e-15)
    assert res.error == pytest.approx(np.linalg.norm(np.asarray(target) - tip), abs=1e-15)
    assert res.reachable == (res.error <= TOL)


def test_defined_in_delta_ik_and_not_re_exported_from_delta():
    """The IK imports the forward kinematics (delta), never the other way round: no circle.
    The result type lives below the solver (in the iteration module the seeds and the box
    solver share) and the solver exports it."""
    from core.kinematics import delta_ik, delta_ik_iteration
    assert solve_tip_ik.__module__ == delta_ik.__name__
    assert TipIKResult.__module__ == delta_ik_iteration.__name__
    assert delta_ik.TipIKResult is TipIKResult and "TipIKResult" in delta_ik.__all__
    assert not hasattr(dk, "solve_tip_ik") and not hasattr(dk, "TipIKResult")


def test_random_reachable_targets_cold_start_all_solved():
    rng = np.random.default_rng(11)
    _, targets = random_reachable(rng, 100)
    for target in targets:
        res = solve_tip_ik(ARM, target)
        assert_consistent(res, target)
        assert res.reachable and res.error <= TOL, (target, res.error)


def test_random_reachable_targets_from_retracted_start_all_solved():
    """No single-arc guess: the iteration itself (with its restarts) from the retracted arm."""
    rng = np.random.default_rng(12)
    _, targets = random_reachable(rng, 40)
    for target in targets:
        res = solve_tip_ik(ARM, target, np.zeros((ARM.n_segments, 3)))
        assert_consistent(res, target)
        assert res.error <= TOL, (target, res.error)


def test_warm_start_near_the_solution_converges_alone():
    rng = np.random.default_rng(13)
    lengths, targets = random_reachable(rng, 30)
    for L, target in zip(lengths, targets):
        near = np.clip(L + rng.uniform(-0.005, 0.005, L.shape), LO, HI)
        res = solve_tip_ik(ARM, target, dk.delta_from_actuators(near, ARM.phi, ARM.L0),
                              restarts=False)
        assert_consistent(res, target)
        assert res.error <= 1e-5 and res.starts == 1


def test_exact_target_returns_its_configuration_without_iterating():
    delta = dk.delta_from_actuators([[0.2, 0.25, 0.23], [0.2, 0.25, 0.22]], ARM.phi, ARM.L0)
    assert np.all(bends(delta) <= ARM.theta_max)
    target = dk.tip_position(ARM, delta)
    res = solve_tip_ik(ARM, target, delta)
    assert res.iterations == 0 and res.error < 1e-12
    np.testing.assert_allclose(res.delta, delta, atol=1e-15)


finite = st.floats(-1.5, 1.5, allow_nan=False)
warm_starts = st.none() | st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6).map(
    lambda v: np.array(v).reshape(2, 3))


@settings(max_examples=40, deadline=None)
@given(st.tuples(finite, finite, finite), warm_starts)
def test_limits_never_exceeded_and_error_is_true_distance(target, delta0):
    # Targets up to ~2.6 m away (mostly unreachable) and warm starts far outside the limits.
    res = solve_tip_ik(ARM, target, delta0)
    assert_consistent(res, target)


@pytest.mark.parametrize("z", [0.83, 0.9, 1.5])
@pytest.mark.parametrize("bent_start", [False, True])
def test_target_above_the_fully_extended_arm(z, bent_start):
    # Every rack <= rack_max, so each backbone (their mean) is <= rack_max and the tip, at most
    # the backbone's arc length from the base, lies within n * rack_max of it; the straight,
    # fully extended arm attains it. Closest distance: z - n * rack_max.
    delta0 = [[0.05, -0.02, 0.1], [-0.03, 0.04, 0.2]] if bent_start else None
    res = solve_tip_ik(ARM, [0.0, 0.0, z], delta0)
    assert_consistent(res, [0.0, 0.0, z])
    assert not res.reachable
    assert res.error == pytest.approx(z - ARM.n_segments * HI, abs=TOL)
    np.testing.assert_allclose(res.lengths, HI, atol=TOL)


def bounded_best(target, starts=8, seed=0):
    """Independent check: SLSQP over the rack box with the bending limit written as
    dx^2 + dy^2 <= (d theta_max)^2 per segment (Delta from eq. 2), from random feasible starts
    (not from the solver's answer); the best feasible distance."""
    M = dk.rack_matrix(ARM.phi)
    bend_max = ARM.rack_radius * ARM.theta_max

    def f(flat):
        p, J = dk.chain_tip_and_jacobian(dk.delta_from_actuators(flat.reshape(2, 3), ARM.phi, ARM.L0),
                                         ARM.L0, ARM.d)
        e = target - p
        return 0.5 * e @ e, -(J.reshape(3, 2, 3) @ M).reshape(3, 6).T @ e

    def slack(flat):
        b = flat.reshape(2, 3) @ M[:2].T
        return bend_max ** 2 - (b ** 2).sum(axis=1)

    rng = np.random.default_rng(seed)
    best = math.inf
    while starts:
        x0 = rng.uniform(LO, HI, 6)
        if np.any(slack(x0) < 0):
            continue
        starts -= 1
        res = minimize(f, x0, jac=True, method="SLSQP", bounds=[(LO, HI)] * 6,
                       constraints=[{"type": "ineq", "fun": slack}],
                       options={"maxiter": 300, "ftol": 1e-14})
        x = np.clip(res.x, LO, HI)
        if np.all(slack(x) >= -1e-9):
            best = min(best, math.sqrt(2 * f(x)[0]))
    return best


@pytest.mark.parametrize("target", [(1.0, 1.0, 1.0), (0.0, 0.0, -1.0), (0.6, 0.0, 0.6),
                                    (0.3, 0.2, -0.5), (0.0, 0.0, -0.15), (-0.069, 0.0, -0.108)])
def test_unreachable_error_matches_independent_bounded_optimiser(target):
    target = np.array(target)
    res = solve_tip_ik(ARM, target)
    assert_consistent(res, target)
    assert not res.reachable
    assert res.error <= bounded_best(target) + TOL


def test_random_targets_never_bend_beyond_theta_max():
    # Tips of random rack lengths over the whole box: most need more bending than theta_max.
    rng = np.random.default_rng(21)
    lengths = rng.uniform(LO, HI, (40, ARM.n_segments, 3))
    targets = dk.tip_position(ARM, dk.delta_from_actuators(lengths, ARM.phi, ARM.L0))
    over = 0
    for target in targets:
        res = solve_tip_ik(ARM, target)
        assert_consistent(res, target)  # racks in the box, every bend <= theta_max
        over += not res.reachable
    assert over > 0  # the limit mattered for some of them


@pytest.mark.parametrize("target", [(0.0, 0.0, -0.15), (-0.069, 0.0, -0.108), (0.2, 0.0, -0.2)])
def test_target_only_reachable_by_bending_beyond_the_limit(target):
    target = np.array(target)
    free = solve_tip_ik(FREE, target)  # the racks alone reach it ...
    assert free.reachable and bends(free.delta).max() > ARM.theta_max
    res = solve_tip_ik(ARM, target)  # ... but only by bending more than theta_max
    assert_consistent(res, target)
    assert not res.reachable and res.error > 0.05
    # The closest feasible configuration: nothing feasible gets nearer (independent optimiser),
    # and the answer bends as far as allowed towards the target.
    assert res.error <= bounded_best(target) + TOL
    assert bends(res.delta).max() == pytest.approx(ARM.theta_max, rel=1e-6)


def test_restarts_escape_the_local_minimum_of_a_poor_warm_start():
    # Racks only (theta up to a full turn): the straight, retracted arm is a poor start for a
    # target curled below the base: alone it stalls at a local minimum (still feasible); the
    # seeded restarts reach the target. (Within theta_max = pi/2 that target is out of reach.)
    target = np.array([-0.069, 0.0, -0.108])
    alone = solve_tip_ik(FREE, target, np.zeros((2, 3)), restarts=False)
    assert alone.starts == 1 and not alone.reachable
    seeded = solve_tip_ik(FREE, target, np.zeros((2, 3)))
    assert seeded.reachable and seeded.starts > 1


@pytest.mark.parametrize("target", [[0.1, 0.2], [[0.1, 0.2, 0.3]], [0.1, float("nan"), 0.3],
                                    [0.1, float("inf"), 0.3], "abc", None])
def test_bad_target_raises_clear_error(target):
    with pytest.raises(ValueError, match="target_xyz"):
        solve_tip_ik(ARM, target)


@pytest.mark.parametrize("delta0", [np.zeros((3, 3)), np.zeros(5), np.full((2, 3), np.nan), "x"])
def test_bad_warm_start_raises_clear_error(delta0):
    with pytest.raises(ValueError, match="delta0"):
        solve_tip_ik(ARM, [0.1, 0.0, 0.4], delta0)


def test_flat_warm_start_accepted():
    res = solve_tip_ik(ARM, [0.1, 0.0, 0.4], np.zeros(6))
    assert res.reachable


def test_wrong_robot_raises():
    with pytest.raises(ValueError, match="extensible"):
        solve_tip_ik(robots.load("soft-arm"), [0.1, 0.0, 0.4])


def test_settings_read_from_robot_file():
    table = tomllib.loads(ARM.source.read_text())["ik"]
    s = IKSettings.from_robot(ARM)
    for key, value in table.items():
        assert getattr(s, key) == value


@pytest.mark.parametrize("ik, match", [({"tolerance": -1.0}, "ik.tolerance"),
                                       ({"max_iterations": 0}, "ik.max_iterations"),
                                       ({"max_iterations": 2.5}, "ik.max_iterations"),
                                       ({"goal_tolerance": 0.01}, "ik.goal_tolerance"),
                                       ({"polish_iterations": -1}, "ik.polish_iterations"),
                                       ({"bogus": 1}, "unknown")])
def test_bad_settings_in_robot_file_raise(ik, match):
    table = tomllib.loads(ARM.source.read_text())
    with pytest.raises(ValueError, match=match):  # refused when the file is read
        solve_tip_ik(robots.parse({**table, "ik": ik}, ARM.source), [0.1, 0.0, 0.4])
