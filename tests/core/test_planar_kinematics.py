"""Planar PCC kinematics against the paper's own formulas, closed forms and finite differences."""

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from hypothesis.extra.numpy import arrays

from core import robots
from core.kinematics import planar

ARM = robots.load("soft-arm")
L = ARM.lengths
KMAX = ARM.kappa_max
kappas = arrays(np.float64, 6, elements=st.floats(-KMAX, KMAX))


def paper_forwkin(kappa, lengths, base=(0.0, 0.0, math.pi / 2)):
    """Algorithm 1's forwKin, literally (needs kappa != 0)."""
    x, y, th = base
    out = [(x, y, th)]
    for k, ln in zip(kappa, lengths):
        th1 = th + k * ln
        x, y = x + math.sin(th1) / k - math.sin(th) / k, y - math.cos(th1) / k + math.cos(th) / k
        th = th1
        out.append((x, y, th))
    return np.array(out)


@settings(max_examples=200, deadline=None)
@given(arrays(np.float64, 6, elements=st.floats(0.5, KMAX)), st.lists(st.booleans(), min_size=6, max_size=6))
def test_fk_matches_papers_forwkin(mag, signs):
    kappa = np.where(signs, mag, -mag)
    np.testing.assert_allclose(planar.forward_kinematics(kappa, L), paper_forwkin(kappa, L), atol=1e-12)


def test_straight_arm_is_a_line_along_plus_y():
    poses = planar.forward_kinematics(np.zeros(6), L)
    np.testing.assert_allclose(poses[:, 0], 0.0, atol=1e-15)
    np.testing.assert_allclose(poses[:, 1], np.arange(7) * 0.0627, atol=1e-15)
    np.testing.assert_allclose(poses[:, 2], math.pi / 2)


def test_positive_curvature_turns_counter_clockwise():
    tip = planar.forward_kinematics(np.full(6, 5.0), L)[-1]
    assert tip[0] < 0  # heading +y turning CCW bends toward -x
    assert tip[2] == pytest.approx(math.pi / 2 + 5.0 * 6 * 0.0627)


def test_six_segments_at_full_curvature_close_the_circle():
    """Paper §3.3: with six segments the tip can touch the base (6 x 60 deg = 360 deg)."""
    exact = planar.forward_kinematics(np.full(6, (math.pi / 3) / 0.0627), L)[-1]
    assert np.hypot(*exact[:2]) < 1e-12
    at_limit = planar.forward_kinematics(np.full(6, KMAX), L)[-1]
    assert np.hypot(*at_limit[:2]) < 1e-4  # 16.7 1/m is 59.99 deg per segment


@settings(max_examples=100, deadline=None)
@given(kappas)
def test_small_curvature_is_smooth_through_zero(kappa):
    """Near kappa = 0 the tip moves as the Jacobian at the straight arm predicts (no 0/0 noise)."""
    eps = 1e-7
    straight, jac0 = planar.tip_jacobian(np.zeros(6), L)
    tip = planar.forward_kinematics(kappa * eps, L)[-1]
    np.testing.assert_allclose(tip, straight + jac0 @ (kappa * eps), atol=1e-12)


def test_batched_equals_loop():
    rng = np.random.default_rng(0)
    k = rng.uniform(-KMAX, KMAX, (4, 5, 6))
    batched = planar.forward_kinematics(k, L)
    assert batched.shape == (4, 5, 7, 3)
    for idx in np.ndindex(4, 5):
        np.testing.assert_allclose(batched[idx], planar.forward_kinematics(k[idx], L), atol=1e-15)


@settings(max_examples=100, deadline=None)
@given(kappas, st.integers(0, 5), st.floats(0.0, 1.0),
       st.tuples(st.floats(-0.05, 0.05), st.floats(-0.05, 0.05)))
def test_point_jacobian_matches_finite_differences(kappa, seg, frac, offset):
    arc = frac * L[seg]
    _, jac = planar.point_jacobian(kappa, L, seg, arc, offset)
    h = 1e-6
    fd = np.empty_like(jac)
    for i in range(6):
        e = np.zeros(6)
        e[i] = h
        fd[:, i] = (planar.point_jacobian(kappa + e, L, seg, arc, offset)[0]
                    - planar.point_jacobian(kappa - e, L, seg, arc, offset)[0]) / (2 * h)
    np.testing.assert_allclose(jac, fd, atol=1e-7)


def test_point_on_arm_matches_fk_at_segment_ends():
    k = np.array([3.0, -7.0, 12.0, 0.0, -16.0, 9.0])
    ends = planar.forward_kinematics(k, L)
    for seg in range(6):
        pose, _ = planar.point_jacobian(k, L, seg, L[seg])
        np.testing.assert_allclose(pose, ends[seg + 1], atol=1e-14)


@settings(max_examples=50, deadline=None)
@given(kappas, st.integers(1, 32))
def test_backbone_samples_lie_on_each_arc(kappa, per_seg):
    pts = planar.sample_backbone(kappa, L, per_seg)
    ends = planar.forward_kinematics(kappa, L)
    assert pts.shape == (6 * per_seg + 1, 3)
    np.testing.assert_allclose(pts[::per_seg], ends, atol=1e-14)
    for i in range(6):
        seg_pts = pts[i * per_seg:(i + 1) * per_seg + 1, :2]
        chords = np.linalg.norm(np.diff(seg_pts, axis=0), axis=1)
        # Equal arc steps subtend equal chords on a circle (or a line).
        step = L[i] / per_seg
        half_turn = abs(kappa[i]) * step / 2
        expected = step * (math.sin(half_turn) / half_turn if half_turn > 1e-12 else 1.0)
        np.testing.assert_allclose(chords, expected, rtol=1e-9, atol=1e-13)


@settings(max_examples=300, deadline=None)
@given(st.floats(-200.0, 200.0), st.floats(0.01, 0.3), st.floats(-math.pi, math.pi),
       st.floats(-1.0, 1.0), st.floats(-1.0, 1.0))
def test_single_segment_ik_round_trip(kappa, length, theta0, x0, y0):
    if abs(kappa * length) > 2 * math.pi - 1e-3:
        return
    start = np.array([x0, y0, theta0])
    end = planar.forward_kinematics([kappa], [length], start)[-1]
    k, ln = planar.single_segment_ik(start, end[:2])
    assert k == pytest.approx(kappa, rel=1e-7, abs=1e-7)
    assert ln == pytest.approx(length, rel=1e-7)


def test_single_segment_ik_is_stable_for_straight_and_nearly_closed_arcs():
    for turn in (0.0, 1e-12, 1e-6, 2 * math.pi - 1e-4, 2 * math.pi - 1e-7):
        k_true = turn / 0.0627
        end = planar.forward_kinematics([k_true], [0.0627], [0.0, 0.0, 0.3])[-1]
        k, ln = planar.single_segment_ik([0.0, 0.0, 0.3], end[:2])
        assert np.isfinite(k) and np.isfinite(ln)
        assert ln == pytest.approx(0.0627, rel=1e-3)
        assert k == pytest.approx(k_true, rel=1e-3, abs=1e-6)


@settings(max_examples=100, deadline=None)
@given(kappas)
def test_fit_arm_recovers_configuration_from_markers(kappa):
    ends = planar.forward_kinematics(kappa, L)
    k, ln = planar.fit_arm(ends[1:, :2])
    np.testing.assert_allclose(k, kappa, atol=1e-6)
    np.testing.assert_allclose(ln, L, rtol=1e-9)


def test_fit_arm_is_batched():
    rng = np.random.default_rng(3)
    k = rng.uniform(-KMAX, KMAX, (100, 6))
    ends = planar.forward_kinematics(k, L)
    kf, lf = planar.fit_arm(ends[:, 1:, :2])
    np.testing.assert_allclose(kf, k, atol=1e-6)
    np.testing.assert_allclose(lf, np.broadcast_to(L, (100, 6)), rtol=1e-9)


def test_shape_errors_are_clear():
    with pytest.raises(ValueError, match="lengths"):
        planar.forward_kinematics(np.zeros(6), np.ones(5))
    with pytest.raises(ValueError, match="markers"):
        planar.fit_arm(np.zeros((6, 3)))
    with pytest.raises(ValueError, match="segment"):
        planar.point_jacobian(np.zeros(6), L, segment=6)
