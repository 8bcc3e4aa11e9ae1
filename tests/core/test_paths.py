"""Motion paths (Fig. 9) for the extensible arm: geometry of the builders, continuity, the tip,
rack and motor speed limits, rack and bending limits and the motor demand round trip."""

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from core import robots
from core.kinematics import delta as dk
from core.planning import paths
from core.robot_schema import tomllib
from core.robot_sections import PathSettings

ARM = robots.load("extensible")
COARSE = PathSettings(rate_hz=20.0, spacing=0.005)  # fast variants for property tests


def check_motion(robot, mp, ps, speed):
    """Invariants every planned path must satisfy."""
    K = len(mp.times)
    n = robot.n_segments
    np.testing.assert_allclose(mp.times, np.arange(K) / ps.rate_hz, atol=1e-12)
    assert mp.targets.shape == (K, 3) and mp.tips.shape == (K, 3)
    assert mp.deltas.shape == (K, n, 3) and mp.lengths.shape == (K, n, 3)
    assert mp.motor_counts.shape == (K, 3 * n) and mp.motor_counts.dtype == np.int64
    # Rack limits, and deltas / tips / errors consistent with the lengths.
    assert np.all(mp.lengths >= robot.rack_min) and np.all(mp.lengths <= robot.rack_max)
    theta = np.hypot(mp.deltas[..., 0], mp.deltas[..., 1]) / robot.rack_radius
    assert np.all(theta <= robot.theta_max)
    np.testing.assert_allclose(dk.robot_rack_lengths(robot, mp.deltas), mp.lengths, atol=1e-12)
    np.testing.assert_allclose(dk.tip_position(robot, mp.deltas), mp.tips, atol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(mp.targets - mp.tips, axis=1), mp.errors, atol=1e-14)
    if K < 2:
        return
    dt = np.diff(mp.times)
    # Speed limits, measured independently from the samples.
    rack_speed = np.abs(np.diff(mp.lengths, axis=0)).reshape(K - 1, -1).max(axis=1) / dt
    assert rack_speed.max() <= robot.rack_speed * (1 + 1e-9)
    assert (np.linalg.norm(np.diff(mp.tips, axis=0), axis=1) / dt).max() <= robot.tip_speed
    assert (np.linalg.norm(np.diff(mp.targets, axis=0), axis=1) / dt).max() <= speed * (1 + 1e-9)
    # No jumps in Delta: each component moves at most ||M||_inf * rack_speed / rate per sample.
    M = dk.rack_matrix(robot.phi)
    bound = np.abs(M).sum(axis=1).max() * robot.rack_speed / ps.rate_hz
    assert np.abs(np.diff(mp.deltas, axis=0)).max() <= bound * (1 + 1e-9)
    assert mp.max_delta_step() <= bound * (1 + 1e-9)
    # Motor speed: finite differences of the integer demands themselves, in counts/s.
    counts_per_s = np.abs(np.diff(mp.motor_counts, axis=0)).max(axis=1) / dt
    assert counts_per_s.max() <= robot.motor_speed * robot.counts_per_metre * (1 + 1e-9)
    assert mp.max_motor_speed() <= robot.motor_speed * (1 + 1e-9)
    # Motor demands: counts of U^-1 L, round trip within rounding (n half-counts at most).
    np.testing.assert_allclose(dk.lengths_from_motor_counts(robot, mp.motor_counts), mp.lengths,
                               atol=n * 0.5 / robot.counts_per_metre + 1e-12)
    U = np.kron(np.triu(np.ones((n, n))), np.eye(3))
    motors = np.linalg.solve(U, mp.lengths.reshape(K, -1).T).T * robot.counts_per_metre
    assert np.abs(mp.motor_counts - motors).max() <= 0.5 + 1e-6


# --- builders ---------------------------------------------------------------------------------

def test_linear_traverse_geometry():
    w = paths.linear_traverse([0.1, 0.0, 0.4], 0.2, "xz", axis=1)
    np.testing.assert_allclose(w, [[0.1, 0.0, 0.3], [0.1, 0.0, 0.5]])


def test_diagonal_traverse_geometry():
    w = paths.diagonal_traverse([0.0, 0.1, 0.4], 0.1, "xy")
    np.testing.assert_allclose(w, [[-0.05, 0.05, 0.4], [0.05, 0.15, 0.4]])
    assert np.linalg.norm(w[1] - w[0]) == pytest.approx(0.1 * math.sqrt(2))


def test_four_corners_is_a_closed_square_in_its_plane():
    w = paths.four_corners([0.0, 0.1, 0.4], 0.1, "yz")
    assert w.shape == (5, 3)
    np.testing.assert_array_equal(w[0], w[-1])
    np.testing.assert_allclose(w[:, 0], 0.0)
    np.testing.assert_allclose(np.linalg.norm(np.diff(w, axis=0), axis=1), 0.1)
    np.testing.assert_allclose(w[:4].mean(axis=0), [0.0, 0.1, 0.4])
    assert paths.four_corners([0, 0, 0.4], 0.1, closed=False).shape == (4, 3)


@pytest.mark.parametrize("kind", paths.PATH_KINDS)
def test_build_path_dispatches(kind):
    builders = {"linear": paths.linear_traverse, "diagonal": paths.diagonal_traverse,
                "corners": paths.four_corners}
    np.testing.assert_array_equal(paths.build_path(kind, [0, 0, 0.4], 0.1, "xy"),
                                  builders[kind]([0, 0, 0.4], 0.1, "xy"))


@pytest.mark.parametrize("args, match", [
    (("linear", [0, 0, 0.4], -0.1, "xy"), "size"),
    (("linear", [0, 0, 0.4], 0.1, "ab"), "plane"),
    (("linear", [0, np.nan, 0.4], 0.1, "xy"), "centre"),
    (("spiral", [0, 0, 0.4], 0.1, "xy"), "kind"),
])
def test_bad_builder_input(args, match):
    with pytest.raises(ValueError, match=match):
        paths.build_path(*args)


@pytest.mark.parametrize("points", [[], [[0, 0]], [[0, 0, np.inf]], "abc"])
def test_bad_polyline(points):
    with pytest.raises(ValueError, match="points"):
        paths.polyline(points)


# --- planning ---------------------------------------------------------------------------------

@pytest.mark.parametrize("kind", paths.PATH_KINDS)
def test_fig9_paths_at_the_default_rate_follow_the_targets(kind):
    ps = PathSettings.from_robot(ARM)
    w = paths.build_path(kind, [0.1, 0.0, 0.45], 0.06, "xy")
    mp = paths.plan_path(ARM, w)
    check_motion(ARM, mp, ps, ARM.tip_speed)
    assert mp.max_error <= 1e-3 and mp.jumps == 0
    np.testing.assert_allclose(mp.targets[0], w[0], atol=1e-12)
    np.testing.assert_allclose(mp.targets[-1], w[-1], atol=1e-12)
    # Every corner is passed within one sample's travel; no faster than the tip speed allows.
    for vertex in w:
        assert np.linalg.norm(mp.targets - vertex, axis=1).min() <= ARM.tip_speed / ps.rate_hz
    length = np.linalg.norm(np.diff(w, axis=0), axis=1).sum()
    assert mp.duration >= length / ARM.tip_speed


def test_rack_speed_limit_slows_the_path():
    slow = dataclasses.replace(ARM, rack_speed=0.01)
    w = paths.linear_traverse([0.05, 0.0, 0.3], 0.05, "xy")
    mp = paths.plan_path(slow, w, settings=COARSE)
    check_motion(slow, mp, COARSE, slow.tip_speed)
    # The most-travelled rack's total travel cannot be covered faster than the rack speed.
    travel = np.abs(np.diff(mp.lengths, axis=0)).sum(axis=0).max()
    assert mp.duration >= travel / slow.rack_speed
    assert mp.duration > 2 * 0.05 / slow.tip_speed  # slowed well below the tip speed


def test_start_delta_starts_at_the_current_posture():
    start = np.array([[0.02, 0.0, 0.1], [0.0, 0.01, 0.15]])
    w = paths.linear_traverse([0.1, 0.05, 0.4], 0.05, "xz")
    mp = paths.plan_path(ARM, w, start_delta=start, speed=0.05, settings=COARSE)
    check_motion(ARM, mp, COARSE, 0.05)
    np.testing.assert_allclose(mp.deltas[0], start, atol=1e-12)
    np.testing.assert_allclose(mp.tips[0], dk.tip_position(ARM, start), atol=1e-12)
    assert mp.max_error <= 1e-3


def test_unreachable_stretch_is_reported_and_still_within_limits():
    # At z = 0.85 every target is farther than n * rack_max = 0.82 m from the base, so no tip
    # gets closer to it than |target| - 0.82 (see the IK test of the fully extended arm).
    w = paths.linear_traverse([0.0, 0.0, 0.85], 0.2, "xy")
    mp = paths.plan_path(ARM, w, settings=COARSE)
    check_motion(ARM, mp, COARSE, ARM.tip_speed)
    reach = ARM.n_segments * ARM.rack_max
    assert np.all(mp.errors >= np.linalg.norm(mp.targets, axis=1) - reach - 1e-12)
    assert mp.errors.min() >= 0.85 - reach - 1e-12


def test_branch_switch_is_counted_and_crossed_within_the_limits():
    # A low traverse from -x to +x: the branch bent towards -x runs into the rack and bending
    # limits; the restarts switch to the branch bent towards +x. The racks cross over at their
    # speed limit (the tip leaves the path, which the errors show), still with no jump between
    # samples.
    w = paths.polyline([[-0.2, 0.0, 0.1], [0.2, 0.0, 0.1]])
    mp = paths.plan_path(ARM, w, settings=COARSE)
    check_motion(ARM, mp, COARSE, ARM.tip_speed)
    assert mp.jumps >= 1
    assert mp.errors[-1] <= 1e-3


def test_motor_limit_slows_racks_moving_in_opposite_directions():
    # Straight arm; segment 1's racks extend from 0.10 to 0.30 m while segment 2's retract from
    # 0.30 to 0.10 m: the tip stays at z = 0.40 m and every rack travels 0.2 m, but motor 1
    # (m1 = L1 - L2) travels 0.4 m. Closed form: the duration is 0.4 m at the planned motor speed
    # min(margin * motor_speed, motor_speed - one count per sample), rounded up to a sample;
    # rack limit alone: 0.2 m / (margin * rack_speed), about half of that.
    ps = PathSettings.from_robot(ARM)
    L = np.array([[[0.10] * 3, [0.30] * 3], [[0.30] * 3, [0.10] * 3]])
    targets = np.array([[0.0, 0.0, 0.4], [0.0, 0.0, 0.4]])
    mp = paths.timed_path(ARM, targets, L, settings=ps)
    check_motion(ARM, mp, ps, ARM.tip_speed)
    v_motor = min(ps.limit_margin * ARM.motor_speed,
                  ARM.motor_speed - ps.rate_hz / ARM.counts_per_metre)
    expected = math.ceil(0.4 / v_motor * ps.rate_hz - 1e-9) / ps.rate_hz
    assert mp.duration == pytest.approx(expected, abs=1e-9)
    assert mp.duration > 1.9 * 0.2 / (ps.limit_margin * ARM.rack_speed)
    np.testing.assert_allclose(mp.lengths[[0, -1]], L, atol=1e-12)
    np.testing.assert_allclose(mp.tips, np.tile([0.0, 0.0, 0.4], (len(mp.times), 1)), atol=1e-12)
    # The same rack travel with both segments extending: motor 1 stays put, motor 2 (m2 = L2)
    # travels 0.2 m, so it takes half as long (the tip, 0.4 m at the tip speed, is not slower).
    same = paths.timed_path(ARM, [[0, 0, 0.2], [0, 0, 0.6]],
                            np.array([[[0.10] * 3] * 2, [[0.30] * 3] * 2]), settings=ps)
    check_motion(ARM, same, ps, ARM.tip_speed)
    assert same.duration == pytest.approx(
        math.ceil(0.2 / v_motor * ps.rate_hz - 1e-9) / ps.rate_hz, abs=1e-9)


def test_timed_path_refuses_lengths_outside_the_limits():
    bent = dk.robot_rack_lengths(ARM, np.array([[0.06, 0.0, 0.2], [0.0, 0.0, 0.2]]))
    with pytest.raises(ValueError, match="theta_max"):  # 2 rad > theta_max, racks in the box
        paths.timed_path(ARM, [[0, 0, 0.4]], bent[None])
    with pytest.raises(ValueError, match="must match"):
        paths.timed_path(ARM, [[0, 0, 0.4]], np.full((2, 2, 3), 0.2))


def test_start_posture_bent_beyond_the_limit_is_brought_within_it():
    start = np.array([[0.09, 0.0, 0.25], [0.0, 0.0, 0.1]])  # 3 rad: racks fine, too bent
    w = paths.linear_traverse([0.1, 0.0, 0.3], 0.04, "xy")
    mp = paths.plan_path(ARM, w, start_delta=start, settings=COARSE)
    check_motion(ARM, mp, COARSE, ARM.tip_speed)
    # Bending scaled back to theta_max along the same direction, extension kept.
    np.testing.assert_allclose(mp.deltas[0], [[ARM.rack_radius * ARM.theta_max, 0.0, 0.25],
                                              [0.0, 0.0, 0.1]], atol=1e-9)


point = st.tuples(st.floats(-0.15, 0.15), st.floats(-0.15, 0.15), st.floats(0.3, 0.5))


def test_degenerate_polyline_is_a_single_sample():
    mp = paths.plan_path(ARM, [[0.1, 0.0, 0.3], [0.1, 0.0, 0.3]], settings=COARSE)
    assert len(mp.times) == 1 and mp.duration == 0.0 and mp.max_error <= 1e-3
    check_motion(ARM, mp, COARSE, ARM.tip_speed)


@settings(max_examples=6, deadline=None)
@given(st.lists(point, min_size=2, max_size=3), st.floats(0.02, 0.1))
def test_random_polylines_respect_limits_and_continuity(points, speed):
    mp = paths.plan_path(ARM, points, speed=speed, settings=COARSE)
    check_motion(ARM, mp, COARSE, speed)


@pytest.mark.parametrize("kwargs, match", [
    ({"speed": 0.2}, "exceeds the tip speed limit"),
    ({"speed": 0.0}, "speed"),
    ({"speed": float("nan")}, "speed"),
    ({"start_delta": np.zeros((3, 3))}, "start_delta"),
])
def test_bad_plan_input(kwargs, match):
    with pytest.raises(ValueError, match=match):
        paths.plan_path(ARM, [[0, 0, 0.4], [0.05, 0, 0.4]], **kwargs)


def test_bad_path_settings_in_robot_file():
    table = tomllib.loads(ARM.source.read_text())
    with pytest.raises(ValueError, match="paths.rate_hz"):  # refused when the file is read
        paths.plan_path(robots.parse({**table, "paths": {"rate_hz": -5}}, ARM.source),
                        [[0, 0, 0.4], [0.05, 0, 0.4]])
