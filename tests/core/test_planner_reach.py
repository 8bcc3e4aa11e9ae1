"""100 % planning success on reachable objects in the left quadrant, and no wrong refusals.

"Reachable" is decided by an independent oracle, not by the planner: dense random sampling of
configurations with core.kinematics.planar, the object centre each one would hold, polished to
an exact final pose by Gauss-Newton steps, and the arm-body clearance checked by dense
backbone sampling. Objects of the paper's sizes (2-5 cm diameter), arm straight (the paper's
start).
"""


import numpy as np
import pytest

from core import robots
from core.kinematics import planar
from core.planning.grasp import GraspRefused, plan_grasp

ARM = robots.load("soft-arm")
L, G = ARM.lengths, ARM.gripper
MARGIN = ARM.planner.clearance_margin
SIZES = (0.010, 0.0175, 0.025)
GRID = [(x, y) for x in np.arange(-0.40, -0.049, 0.05) for y in np.arange(0.05, 0.401, 0.05)]


def object_point(kappa, radius):
    """Object centre held by the gripper at the final radius r_o + g_off (palm + r_a left)."""
    tip = planar.forward_kinematics(kappa, L, ARM.base_pose)[..., -1, :]
    return planar.point_in_frame(tip, (G.w_off_along, 2 * G.g_off + radius))


def gap(kappa, center, radius, per_segment=64):
    bb = planar.sample_backbone(kappa, L, per_segment, ARM.base_pose)
    return np.hypot(bb[..., 0] - center[0], bb[..., 1] - center[1]).min(-1) - ARM.half_width - radius


@pytest.fixture(scope="module")
def samples():
    rng = np.random.default_rng(1)
    return rng.uniform(-ARM.kappa_max, ARM.kappa_max, (60000, 6))


def witness(samples, q, center, radius, extra=0.001):
    """A final configuration with the arm at least MARGIN + extra clear, or None.

    ``q`` are the object centres the sampled configurations would hold."""
    d = np.hypot(q[:, 0] - center[0], q[:, 1] - center[1])
    near = np.flatnonzero(d < 0.03)
    if near.size == 0:
        return None
    near = near[np.argsort(d[near])][:200]
    clear = near[gap(samples[near], center, radius, 8) > MARGIN + extra]
    offset = (G.w_off_along, 2 * G.g_off + radius)
    for k in samples[clear[:6]]:
        # Gauss-Newton projection onto the final pose (min-norm steps, clipped to the limits).
        for _ in range(30):
            tip, jac = planar.tip_jacobian(k, L, offset=offset, base_pose=ARM.base_pose)
            err = tip[:2] - center
            if np.abs(err).max() < 1e-10:
                break
            k = np.clip(k - np.linalg.pinv(jac[:2]) @ err, -ARM.kappa_max, ARM.kappa_max)
        if np.abs(object_point(k, radius) - center).max() < 1e-7 and (
                gap(k, center, radius) > MARGIN + extra):
            return k
    return None


@pytest.mark.parametrize("radius", SIZES)
def test_every_reachable_left_quadrant_object_is_planned(samples, radius):
    reachable = refused = 0
    q = object_point(samples, radius)
    for x, y in GRID:
        center = np.array([x, y])
        w = witness(samples, q, center, radius)
        try:
            plan = plan_grasp(ARM, np.zeros(6), center, radius)
        except GraspRefused as exc:
            refused += 1
            assert w is None, f"refused ({exc}) but the oracle reaches {center}: {w}"
            continue
        if w is not None:
            reachable += 1
            assert plan.success, f"object at {center}, r={radius}: {plan.summary()}"
    # Not vacuous: most of the quadrant grid is reachable and some of it is refused.
    assert reachable >= 30 and refused >= 3
