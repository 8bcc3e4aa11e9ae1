"""Grasp-planner numerics against independent references: the kinematics module, finite
differences, dense sampling of the backbone and scipy."""

import math

import numpy as np
import pytest

from core import robots
from core.kinematics import planar
from core.planning import grasp_solver as gs
from core.planning import solver_kernel as sk
from core.planning.arm_model import ArmModel
from core.planning.clearance import certify_lines, gripper_clearance
from core.planning.feasibility import best_start

ARM = robots.load("soft-arm")
L = ARM.lengths
MODEL = ArmModel.from_robot(ARM)
RNG = np.random.default_rng(20150615)
KAPPAS = RNG.uniform(-ARM.kappa_max, ARM.kappa_max, (8, 6))
KAPPAS[0] = 0.0
KAPPAS[1, 2] = 1e-7  # nearly straight segment (series branch)


def dense_min_distance(kappa, center, per_segment=4000):
    """Distance from a point to the backbone by dense sampling, per segment (independent)."""
    bb = planar.sample_backbone(kappa, L, per_segment, ARM.base_pose)
    d = np.hypot(bb[:, 0] - center[0], bb[:, 1] - center[1])
    return np.array([d[j * per_segment:(j + 1) * per_segment + 1].min() for j in range(6)])


@pytest.mark.parametrize("k", range(len(KAPPAS)))
def test_point_and_jacobian_match_kinematics_module(k):
    offset = (0.035, 0.01 + 0.07)
    q, th, J, _ = MODEL.point(KAPPAS[k][None], complex(*offset))
    pose, jac = planar.tip_jacobian(KAPPAS[k], L, offset=offset, base_pose=ARM.base_pose)
    assert abs(q[0] - complex(pose[0], pose[1])) < 1e-14
    assert abs(th[0] - pose[2]) < 1e-14
    np.testing.assert_allclose(J[0].real, jac[0], atol=1e-14)
    np.testing.assert_allclose(J[0].imag, jac[1], atol=1e-14)
    qp, thp = MODEL.point_py(KAPPAS[k].tolist(), complex(*offset))
    assert abs(qp - q[0]) < 1e-14 and abs(thp - th[0]) < 1e-14


@pytest.mark.parametrize("k", range(len(KAPPAS)))
def test_hessian_matches_finite_differences_of_the_jacobian(k):
    off = 0.035 + 0.05j
    _, _, _, H = MODEL.point(KAPPAS[k][None], off)
    h = 1e-6
    fd = np.empty((6, 6), complex)
    for i in range(6):
        e = np.zeros(6)
        e[i] = h
        _, _, Jp, _ = MODEL.point((KAPPAS[k] + e)[None], off, hessian=False)
        _, _, Jm, _ = MODEL.point((KAPPAS[k] - e)[None], off, hessian=False)
        fd[:, i] = (Jp[0] - Jm[0]) / (2 * h)
    np.testing.assert_allclose(H[0], fd, atol=1e-9 * np.abs(H).max() + 1e-12)
    np.testing.assert_allclose(H[0], H[0].T, atol=1e-15)


@pytest.mark.parametrize("k", range(len(KAPPAS)))
def test_solver_kernel_hessian_and_jacobian_match_the_batched_reference(k):
    lam = RNG.normal(size=2) * 300
    kn = sk.Kernel(MODEL, -0.2 + 0.2j, 0.035 + 0.04j, np.zeros(6), np.full(6, 1.5), None)
    p = sk.PointEval(kn, KAPPAS[k].tolist())
    rows = np.array(kn.kkt_rows(p, lam))
    q, _, J, H = MODEL.point(KAPPAS[k][None], 0.035 + 0.04j)
    W = np.diag(np.full(6, 3.0)) - (lam[0] * H[0].real + lam[1] * H[0].imag)
    np.testing.assert_allclose(rows[:, :6], W, atol=1e-12)
    np.testing.assert_allclose(rows[:, 6], -J[0].real, atol=1e-15)
    np.testing.assert_allclose(np.array(p.J), J[0], atol=1e-15)
    assert abs(p.e - (q[0] - (-0.2 + 0.2j))) < 1e-14
    assert p.f == pytest.approx(1.5 * np.sum(KAPPAS[k] ** 2), rel=1e-14)


@pytest.mark.parametrize("k", range(len(KAPPAS)))
def test_arc_distances_are_exact_against_dense_sampling(k):
    for center in RNG.uniform([-0.4, -0.1], [0.4, 0.45], (4, 2)):
        c = complex(*center)
        dist, s = MODEL.arc_distances(KAPPAS[k], c)
        dense = dense_min_distance(KAPPAS[k], center)
        # Dense samples can only be farther than the true minimum, by < half a sample spacing.
        assert np.all(dist <= dense + 1e-12)
        assert np.all(dist >= dense - 1e-5)
        # The reported closest points really are at that distance.
        p, _ = MODEL.arc_points(KAPPAS[k][None], s)
        np.testing.assert_allclose(np.abs(p[0] - c), dist, atol=1e-12)
        gap = dist.min() - ARM.half_width - 0.02
        assert MODEL.body_clearance(KAPPAS[k], c, 0.02) == pytest.approx(gap, abs=1e-13)
        assert MODEL.clearance_py(KAPPAS[k].tolist(), c, 0.02) == pytest.approx(gap, abs=1e-13)


def test_arc_point_jacobian_matches_finite_differences():
    s = RNG.uniform(0, L[0], (3, 6))
    _, J = MODEL.arc_points(KAPPAS[2:5], s)
    fd = np.empty_like(J)
    for i in range(6):
        e = np.zeros(6)
        e[i] = 1e-6
        pp, _ = MODEL.arc_points(KAPPAS[2:5] + e, s)
        pm, _ = MODEL.arc_points(KAPPAS[2:5] - e, s)
        fd[:, :, i] = (pp - pm) / 2e-6
    np.testing.assert_allclose(J, fd, atol=1e-9)


def test_gripper_clearance_against_a_sampled_gripper():
    g = ARM.gripper
    for k in KAPPAS[:4]:
        tip = planar.forward_kinematics(k, L, ARM.base_pose)[-1]
        s = np.linspace(0, g.length, 20001)
        pts = tip[:2] + s[:, None] * np.array([math.cos(tip[2]), math.sin(tip[2])])
        for center in RNG.uniform([-0.4, 0.0], [0.4, 0.5], (3, 2)):
            dense = np.hypot(*(pts - center).T).min() - g.half_width - 0.015
            got = gripper_clearance(MODEL, k, complex(*center), 0.015, g.length, g.half_width)
            assert got == pytest.approx(dense, abs=1e-5)


def test_line_certificate_is_a_true_lower_bound_and_not_vacuous():
    rng = np.random.default_rng(20150615)  # its own data whatever ran before (xdist reorders)
    center, radius = -0.12 + 0.25j, 0.02
    a = rng.uniform(-10, 10, (30, 6))
    b = np.clip(a + rng.uniform(-6, 6, (30, 6)), -ARM.kappa_max, ARM.kappa_max)
    cert = certify_lines(MODEL, a, b, center, radius, required=0.0, samples=8)
    tau = np.linspace(0, 1, 801)
    cfg = a[:, None, :] + tau[:, None] * (b - a)[:, None, :]
    bb = planar.sample_backbone(cfg, L, 64, ARM.base_pose)
    dense = np.hypot(bb[..., 0] - center.real, bb[..., 1] - center.imag).min(-1)
    dense = (dense - ARM.half_width - radius).min(axis=1)
    assert np.all(cert.lower_bound <= dense + 1e-9)
    # Lines certified clear really are clear, and the bound is tight where it matters.
    clear = cert.lower_bound >= 0
    assert np.all(dense[clear] >= 0)
    touching = dense < 0
    assert touching.any() and clear.any()
    assert np.all(cert.lower_bound[touching] < 0)
    # The sampled minimum is a real sample (never below the truth, up to the dense reference's
    # own sampling) and within the certificate's sampling slack (5 mm by default) above it: each
    # line gets enough samples for its own Lipschitz rate, no more (the faster planner's choice).
    assert np.all(cert.sampled_min >= dense - 1e-3)
    assert np.all(cert.sampled_min <= dense + 0.005)


def _paper_constraints(kappa, phi, center, ra):
    """Algorithm 1's equality constraints in (kappa, phi), from the kinematics module."""
    tip = planar.forward_kinematics(kappa, L, ARM.base_pose)[-1]
    w = planar.point_in_frame(tip, ARM.gripper.w_off)
    return np.array([w[0] - center[0] - ra * math.cos(phi), w[1] - center[1] - ra * math.sin(phi),
                     math.remainder(tip[2] - phi - math.pi / 2, 2 * math.pi)])


@pytest.mark.parametrize("seed", range(6))
def test_solver_converges_to_a_kkt_point_of_the_papers_problem(seed):
    rng = np.random.default_rng(seed)
    center = np.array([rng.uniform(-0.25, -0.1), rng.uniform(0.12, 0.28)])
    ra = rng.uniform(0.04, 0.15)
    off = complex(ARM.gripper.w_off_along, ARM.gripper.g_off + ra)
    # Start where the planner starts its first radius: the best cached table configuration.
    x0 = best_start(MODEL, complex(*center), off, np.zeros(6), np.ones(6), 1024)
    res = gs.solve(MODEL, complex(*center), off, x0, np.zeros(6), np.ones(6))
    assert res.ok
    phi = planar.forward_kinematics(res.kappa, L, ARM.base_pose)[-1, 2] - math.pi / 2
    assert np.abs(_paper_constraints(res.kappa, phi, center, ra)).max() < 1e-8
    # Stationarity of the Lagrangian on the free variables, with multipliers from least squares
    # and the constraint Jacobian by finite differences of the kinematics module.
    z = np.r_[res.kappa, phi]
    Jc = np.empty((3, 7))
    for i in range(7):
        e = np.zeros(7)
        e[i] = 1e-7
        Jc[:, i] = (_paper_constraints((z + e)[:6], (z + e)[6], center, ra)
                    - _paper_constraints((z - e)[:6], (z - e)[6], center, ra)) / 2e-7
    grad = np.r_[2 * res.kappa, 0.0]
    free = np.r_[np.abs(res.kappa) < ARM.kappa_max - 1e-9, True]
    lam, *_ = np.linalg.lstsq(Jc[:, free].T, grad[free], rcond=None)
    assert np.abs(grad[free] - Jc[:, free].T @ lam).max() < 1e-5 * max(1, np.abs(grad).max())


def test_tangent_predictor_matches_finite_differences_of_solutions():
    c = -0.2 + 0.22j
    ra, h = 0.12, 1e-5
    go, wa = ARM.gripper.g_off, ARM.gripper.w_off_along
    base = gs.solve(MODEL, c, complex(wa, go + ra), np.zeros(6), np.zeros(6), np.ones(6),
                    tangent=True)
    up = gs.solve(MODEL, c, complex(wa, go + ra + h), base.kappa, np.zeros(6), np.ones(6))
    dn = gs.solve(MODEL, c, complex(wa, go + ra - h), base.kappa, np.zeros(6), np.ones(6))
    assert base.ok and up.ok and dn.ok
    np.testing.assert_allclose(base.dkappa_dr, (up.kappa - dn.kappa) / (2 * h), rtol=1e-3,
                               atol=1e-3)


def test_clearance_constrained_solve_keeps_the_body_out_of_the_disk():
    # An object close to the base whose approach circle makes the plain optimum (from a straight
    # arm) cut through it.
    c, r_o = -0.01 + 0.07j, 0.02
    go, wa = ARM.gripper.g_off, ARM.gripper.w_off_along
    rho = r_o + ARM.half_width + 0.002
    off = complex(wa, go + 0.05)
    plain = gs.solve(MODEL, c, off, np.zeros(6), np.zeros(6), np.ones(6))
    assert plain.ok
    assert MODEL.body_clearance(plain.kappa, c, r_o) < 0.002   # the plain optimum touches
    res = gs.solve(MODEL, c, off, plain.kappa, np.zeros(6), np.ones(6), plain.lam,
                   gs.Clearance(c, rho))
    assert res.ok and res.violation < 1e-8
    dense = dense_min_distance(res.kappa, (c.real, c.imag)).min() - ARM.half_width - r_o
    assert dense >= 0.002 - 1e-6
    assert res.cost >= plain.cost - 1e-9           # constraints can only cost more
