"""Delta kinematics (delta.py) against the screw exponential, finite differences, fibre lengths
measured on the arc and the paper's printed eq. (3)."""

import math

import numpy as np
import pytest
import scipy.linalg
from hypothesis import given, settings, strategies as st

from core import robots
from core.kinematics import delta as dk

ARM = robots.load("extensible")
D, L0 = ARM.d, ARM.L0
bend = st.floats(-0.25, 0.25)            # |theta| up to ~12 rad with d = 0.03
elong = st.floats(-0.03, 0.40)
deltas = st.tuples(bend, bend, elong).map(np.array)
phis = st.floats(0.0, 2 * math.pi, exclude_max=True)


def skew(w):
    return np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])


def twist(delta, l0=L0, d=D):
    """Body twist of the constant-curvature arc over unit time: bend rate about (-dy, dx, 0)/d
    (so dx > 0 turns z toward +x), advance L = l0 + dL along local z."""
    dx, dy, dl = delta
    X = np.zeros((4, 4))
    X[:3, :3] = skew(np.array([-dy, dx, 0.0]) / d)
    X[2, 3] = l0 + dl
    return X


def reference_transform(delta, l0=L0, d=D):
    """Arc end frame as the matrix exponential of the twist (independent of A, B and series)."""
    return scipy.linalg.expm(twist(delta, l0, d))


def printed_matrix(phi):
    """Eq. (3) exactly as printed in the paper."""
    c, s = math.cos, math.sin
    return np.array([
        [-2 * c(phi) / 3, 2 * c(phi + math.pi / 3) / 3, 2 * c(phi - math.pi / 3) / 3],
        [2 * s(phi) / 3, -2 * s(phi + math.pi / 3) / 3, 2 * s(phi - math.pi / 3) / 3],
        [1 / 3, 1 / 3, 1 / 3],
    ])


# --- segment transform ------------------------------------------------------------------------

@settings(max_examples=80, deadline=None)
@given(deltas)
def test_segment_transform_is_the_arc_exponential(delta):
    np.testing.assert_allclose(dk.segment_transform(delta, L0, D), reference_transform(delta),
                               atol=1e-11)


def test_segment_transform_at_zero_is_the_straight_limit():
    for dl in (0.0, 0.2):
        T = dk.segment_transform([0.0, 0.0, dl], L0, D)
        expected = np.eye(4)
        expected[2, 3] = L0 + dl
        assert np.all(np.isfinite(T))
        np.testing.assert_array_equal(T, expected)
        T, dT = dk.segment_transform_and_jacobian([0.0, 0.0, dl], L0, D)
        assert np.all(np.isfinite(dT))


@pytest.mark.parametrize("theta", [1e-300, 1e-12, 1e-8, 1e-4, 0.0499999999, 0.05, 0.0500000001, 0.3])
@pytest.mark.parametrize("direction", [0.0, 1.0, -2.5])
def test_segment_transform_near_zero_and_at_the_series_switch(theta, direction):
    delta = np.array([D * theta * math.cos(direction), D * theta * math.sin(direction), 0.1])
    np.testing.assert_allclose(dk.segment_transform(delta, L0, D), reference_transform(delta),
                               atol=1e-14, rtol=0)


def test_batched_transform_matches_single():
    rng = np.random.default_rng(3)
    batch = rng.uniform([-0.2, -0.2, 0.0], [0.2, 0.2, 0.3], (4, 5, 3))
    out = dk.segment_transform(batch, L0, D)
    for idx in np.ndindex(4, 5):
        np.testing.assert_allclose(out[idx], reference_transform(batch[idx]), atol=1e-11)


def test_forward_kinematics_chains_without_twist():
    rng = np.random.default_rng(4)
    chain = rng.uniform([-0.1, -0.1, 0.0], [0.1, 0.1, 0.3], (3, 3))
    frames = dk.forward_kinematics(chain, L0, D)
    expected = np.eye(4)
    np.testing.assert_array_equal(frames[0], expected)
    for i in range(3):
        expected = expected @ reference_transform(chain[i])
        np.testing.assert_allclose(frames[i + 1], expected, atol=1e-11)


# --- Jacobians --------------------------------------------------------------------------------

def central_difference(f, x, h=1e-7):
    cols = []
    for j in range(x.size):
        e = np.zeros_like(x)
        e.flat[j] = h
        cols.append((f(x + e) - f(x - e)) / (2 * h))
    return np.stack(cols, axis=-1)


@settings(max_examples=60, deadline=None)
@given(deltas)
def test_segment_jacobian_matches_finite_differences(delta):
    _, dT = dk.segment_transform_and_jacobian(delta, L0, D)
    fd = central_difference(lambda x: dk.segment_transform(x, L0, D), delta)  # (4, 4, 3)
    np.testing.assert_allclose(np.moveaxis(dT, 0, -1), fd, atol=1e-6)


@pytest.mark.parametrize("delta", [[0.0, 0.0, 0.0], [0.0, 0.0, 0.2], [1e-9, 0.0, 0.1],
                                   [D * 0.05, 0.0, 0.1]])
def test_segment_jacobian_at_and_near_zero(delta):
    delta = np.array(delta)
    _, dT = dk.segment_transform_and_jacobian(delta, L0, D)
    fd = central_difference(lambda x: reference_transform(x), delta, h=1e-6)
    np.testing.assert_allclose(np.moveaxis(dT, 0, -1), fd, atol=1e-7)


@settings(max_examples=60, deadline=None)
@given(st.lists(deltas, min_size=1, max_size=3))
def test_chain_tip_jacobian_matches_finite_differences(chain):
    chain = np.array(chain)
    n = len(chain)
    p, J = dk.chain_tip_and_jacobian(chain, L0, D)
    np.testing.assert_allclose(p, dk.forward_kinematics(chain, L0, D)[-1, :3, 3], atol=1e-14)
    fd = central_difference(
        lambda x: dk.forward_kinematics(x.reshape(n, 3), L0, D)[-1, :3, 3], chain.ravel())
    np.testing.assert_allclose(J, fd, atol=2e-6)


# --- rack map ---------------------------------------------------------------------------------

def fibre_length(delta, beta, d=D, samples=2000):
    """Length of the fibre at radius d, angle beta around the backbone, measured on the arc:
    sum of chords between points T(s) (d cos beta, d sin beta, 0) for s in [0, 1], with
    T(s) = expm(s X) built by repeated multiplication, plus one Richardson step."""
    def chords(m):
        step = scipy.linalg.expm(twist(delta, L0, d) / m)
        point = np.array([d * math.cos(beta), d * math.sin(beta), 0.0, 1.0])
        pts = [point]
        T = np.eye(4)
        for _ in range(m):
            T = T @ step
            pts.append(T @ point)
        return np.linalg.norm(np.diff(np.array(pts)[:, :3], axis=0), axis=1).sum()
    return (4 * chords(samples) - chords(samples // 2)) / 3


@settings(max_examples=25, deadline=None)
@given(phis, st.tuples(st.floats(-0.1, 0.1), st.floats(-0.1, 0.1), st.floats(0.1, 0.35)).map(np.array))
def test_fibre_lengths_on_the_arc_map_back_to_delta(phi, delta):
    # Racks sit at beta_j = -phi + 2 pi (j - 1) / 3 (Fig. 5: phi is rack 1's angle to local x).
    betas = [-phi + 2 * math.pi * j / 3 for j in range(3)]
    lengths = np.array([fibre_length(delta, b) for b in betas])
    np.testing.assert_allclose(dk.actuators_from_delta(delta, phi, L0), lengths, atol=1e-9)
    np.testing.assert_allclose(dk.delta_from_actuators(lengths, phi, L0), delta, atol=1e-9)


@pytest.mark.parametrize("phi", [0.0, 2 * math.pi / 3, math.pi])
def test_printed_matrix_is_singular_where_the_corrected_one_is_not(phi):
    assert abs(np.linalg.det(printed_matrix(phi))) < 1e-12
    assert np.linalg.det(dk.rack_matrix(phi)) == pytest.approx(2 * math.sqrt(3) / 9, abs=1e-12)


@settings(max_examples=100, deadline=None)
@given(phis)
def test_rack_matrix_invertible_and_rows_1_3_as_printed(phi):
    M = dk.rack_matrix(phi)
    assert np.linalg.det(M) == pytest.approx(2 * math.sqrt(3) / 9, abs=1e-12)
    np.testing.assert_allclose(M[[0, 2]], printed_matrix(phi)[[0, 2]], atol=1e-15)
    np.testing.assert_allclose(dk.rack_matrix_inverse(phi) @ M, np.eye(3), atol=1e-12)


@settings(max_examples=50, deadline=None)
@given(phis, st.tuples(st.floats(0.05, 0.41), st.floats(0.05, 0.41), st.floats(0.05, 0.41)).map(np.array))
def test_actuator_map_round_trip(phi, lengths):
    np.testing.assert_allclose(
        dk.actuators_from_delta(dk.delta_from_actuators(lengths, phi, L0), phi, L0), lengths,
        atol=1e-14)


# --- conventions ------------------------------------------------------------------------------

@settings(max_examples=50, deadline=None)
@given(st.floats(1e-4, 0.18), elong)
def test_positive_dx_bends_toward_plus_x_and_dy_toward_plus_y(mag, dl):
    # theta = mag / d up to 6 rad (< 2 pi): the tip is displaced toward the bend direction.
    tip_x = dk.segment_transform([mag, 0.0, dl], L0, D)[:3, 3]
    tip_y = dk.segment_transform([0.0, mag, dl], L0, D)[:3, 3]
    assert tip_x[0] > 0 and abs(tip_x[1]) < 1e-15
    assert tip_y[1] > 0 and abs(tip_y[0]) < 1e-15


@settings(max_examples=100, deadline=None)
@given(st.floats(0.0, math.pi * D), st.floats(0, 2 * math.pi), elong)
def test_theta_is_the_angle_between_base_and_tip_z(mag, direction, dl):
    delta = [mag * math.cos(direction), mag * math.sin(direction), dl]
    z_tip = dk.segment_transform(delta, L0, D)[:3, 2]
    angle = math.atan2(np.linalg.norm(np.cross([0, 0, 1.0], z_tip)), z_tip[2])
    assert angle == pytest.approx(math.hypot(delta[0], delta[1]) / D, abs=1e-9)


def test_motor_map_is_block_upper_triangular_and_round_trips():
    n = 3
    U = np.zeros((3 * n, 3 * n))
    for i in range(n):
        for j in range(i, n):
            U[3 * i:3 * i + 3, 3 * j:3 * j + 3] = np.eye(3)
    np.testing.assert_array_equal(dk.motor_matrix(n), U)
    L = np.random.default_rng(5).uniform(0.05, 0.41, (7, n, 3))
    m = dk.motors_from_lengths(L)
    np.testing.assert_allclose(m.reshape(7, -1), np.linalg.solve(U, L.reshape(7, -1).T).T, atol=1e-15)
    np.testing.assert_allclose(dk.lengths_from_motors(m), L, atol=1e-15)


# --- limits: rack box and bending disc ----------------------------------------------------------

def _in_limits(L, tol=1e-12):
    delta = dk.delta_from_actuators(L, ARM.phi, ARM.L0)
    theta = np.hypot(delta[..., 0], delta[..., 1]) / ARM.d
    return (np.all(L >= ARM.rack_min - tol, axis=(-2, -1)) & np.all(L <= ARM.rack_max + tol, axis=(-2, -1))
            & np.all(theta <= ARM.theta_max, axis=-1))


def test_bend_angles_is_the_bend_per_segment():
    delta = np.array([[0.03, 0.04, 0.1], [0.0, -0.015, 0.0]])
    np.testing.assert_allclose(dk.bend_angles(delta, D), [0.05 / D, 0.015 / D])


@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(-0.2, 0.7), min_size=6, max_size=6).map(lambda v: np.reshape(v, (2, 3))))
def test_limit_rack_lengths_lands_in_the_limits_and_keeps_feasible_lengths(L):
    out = dk.limit_rack_lengths(ARM, L)
    assert _in_limits(out)
    clipped = np.clip(L, ARM.rack_min, ARM.rack_max)
    d_in = dk.delta_from_actuators(clipped, ARM.phi, ARM.L0)
    d_out = dk.delta_from_actuators(out, ARM.phi, ARM.L0)
    # Extension kept, bending scaled (same direction, never larger) after clipping to the box.
    np.testing.assert_allclose(d_out[:, 2], d_in[:, 2], atol=1e-12)
    for i in range(2):
        assert d_out[i, 0] * d_in[i, 1] - d_out[i, 1] * d_in[i, 0] == pytest.approx(0, abs=1e-12)
        assert np.hypot(*d_out[i, :2]) <= np.hypot(*d_in[i, :2]) + 1e-15
    if _in_limits(L, tol=0.0):
        np.testing.assert_array_equal(out, L)


def test_feasible_set_is_convex_along_random_chords():
    # Straight lines between feasible rack lengths stay feasible (plan_path and joint_move rely
    # on it): a box intersected with one elliptic cylinder per segment.
    rng = np.random.default_rng(8)
    a = dk.limit_rack_lengths(ARM, rng.uniform(0.05, 0.41, (500, 2, 3)))
    b = dk.limit_rack_lengths(ARM, rng.uniform(0.05, 0.41, (500, 2, 3)))
    s = rng.uniform(0, 1, (500, 1, 1))
    assert np.all(_in_limits(a + s * (b - a), tol=1e-12))
