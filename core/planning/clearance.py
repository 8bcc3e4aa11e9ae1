"""Arm-to-object clearance: exact at a configuration, certified along straight lines in kappa.

The arm body is the backbone swept by its half-width; the gripper is excluded (it is meant to
reach around the object). For a configuration the clearance is computed exactly, segment by
segment (closest point of each constant-curvature arc, :meth:`ArmModel.arc_distances`). Along
the straight line kappa(tau) = kappa_a + tau (kappa_b - kappa_a), tau in [0, 1], which is what
the curvature controller interpolates between waypoints, no backbone point moves faster than
Lambda = sum_k |kappa_b,k - kappa_a,k| L_k (arc length from segment k to the tip) per unit tau
(:meth:`ArmModel.displacement_bound`). So on an interval [t0, t1] with clearances c0, c1 at
its ends the clearance is at least (c0 + c1)/2 - Lambda (t1 - t0)/2. :func:`certify_lines`
samples coarsely and bisects only the intervals whose bound is not yet good enough, so the
result is a guaranteed lower bound, not a sampled estimate.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from core.planning.arm_model import ArmModel

Array = npt.NDArray[np.float64]


def body_clearance(model: ArmModel, kappas: Array, center: complex, radius: float) -> Array:
    """Distance from the arm body (backbone +- half-width) to the object's disk edge.

    Args:
        kappas: (..., N) configurations.
        center: Object centre, complex.
        radius: Object radius (m).

    Returns:
        (...,) clearance in metres; negative means the arm overlaps the object.
    """
    return model.body_clearance(np.asarray(kappas, float), center, radius)


def gripper_clearance(model: ArmModel, kappa: Array, center: complex, radius: float,
                      length: float, half_width: float) -> float:
    """Distance from a straight gripper of the given length and half-width to the disk edge."""
    root, th = model.point_py(np.asarray(kappa, float).tolist())
    heading = complex(np.cos(th), np.sin(th))
    along = ((center - root) * heading.conjugate()).real
    closest = root + heading * min(max(along, 0.0), length)
    return float(abs(center - closest) - half_width - radius)


@dataclasses.dataclass(frozen=True)
class LineCertificate:
    """Clearance along straight lines in kappa.

    Attributes:
        lower_bound: (n,) guaranteed lower bound of the body clearance along each line (m).
        sampled_min: (n,) smallest clearance at the sampled configurations (m).
        worst_tau: (n,) tau of the smallest sampled clearance.
        end_clearance: (n,) clearance at each line's end configuration (tau = 1).
        evaluations: number of configurations evaluated in total.
    """

    lower_bound: Array
    sampled_min: Array
    worst_tau: Array
    end_clearance: Array
    evaluations: int


@functools.lru_cache(maxsize=8)
def _taus(samples: int) -> Array:
    tau = np.linspace(0.0, 1.0, samples + 1)
    tau.flags.writeable = False
    return tau


def certify_lines(
    model: ArmModel,
    starts: Array,
    ends: Array,
    center: complex,
    radius: float,
    required: float = 0.0,
    samples: int = 8,
    max_depth: int = 8,
    slack: float = 0.005,
) -> LineCertificate:
    """Lower-bound the body clearance along straight lines in kappa.

    Args:
        model: Arm model.
        starts, ends: (n, N) line end configurations.
        center, radius: Object disk.
        required: Clearance the caller needs; intervals whose bound is already >= this are
            not refined further.
        samples: Least initial number of intervals per line.
        max_depth: Maximum number of bisection rounds.
        slack: Target Lipschitz slack of the initial sampling (m); more samples are taken (up
            to 64 per line) for lines whose configurations move a lot.

    Returns:
        :class:`LineCertificate`.
    """
    a = np.asarray(starts, float)
    b = np.asarray(ends, float)
    return certify_function(lambda k: model.body_clearance(k, center, radius),
                            model.displacement_bound(b - a), a, b, required, samples, max_depth,
                            slack)


def certify_function(
    evaluate: Callable[[Array], Array],
    lam: Array,
    starts: Array,
    ends: Array,
    required: float = 0.0,
    samples: int = 8,
    max_depth: int = 8,
    slack: float = 0.005,
) -> LineCertificate:
    """Lower-bound any clearance along straight lines in kappa, given its Lipschitz rate.

    Args:
        evaluate: (..., N) configurations -> (...,) clearance (m), exact at each configuration.
        lam: (n,) bound on how fast the clearance can change per unit tau along each line
            (m), e.g. :meth:`ArmModel.displacement_bound`.
        starts, ends, required, samples, max_depth, slack: as :func:`certify_lines`.

    Returns:
        :class:`LineCertificate`.
    """
    a = np.asarray(starts, float)
    b = np.asarray(ends, float)
    lam = np.asarray(lam, float)                                  # (n,) per unit tau
    # Enough samples that the Lipschitz slack Lambda / (2 S) stays below `slack`, so that
    # usually one batched evaluation settles every line and no bisection is needed.
    samples = int(min(max(samples, np.ceil(lam.max(initial=0.0) / (2.0 * slack))), 64))
    tau = _taus(samples)
    clr = evaluate(a[:, None, :] + tau[:, None] * (b - a)[:, None, :])  # (n, S+1)
    evaluations = clr.size
    sampled_min = clr.min(axis=1)
    worst_tau = tau[clr.argmin(axis=1)]
    lb = 0.5 * (clr[:, :-1] + clr[:, 1:]) - (0.5 / samples) * lam[:, None]
    bound = lb.min(axis=1)
    # Bisect intervals that might hide a dip below `required` and whose ends are clear.
    refine = (lb < required) & (np.minimum(clr[:, :-1], clr[:, 1:]) >= required)
    if refine.any():
        li, j = np.nonzero(refine)
        t0, t1 = tau[j], tau[j + 1]
        c0, c1 = clr[li, j], clr[li, j + 1]
        bound = np.where(refine.any(axis=1), np.inf, bound)
        keep = ~refine
        for line in np.unique(li):
            bound[line] = min(bound[line], lb[line][keep[line]].min(initial=np.inf))
        for depth in range(max_depth):
            tm = 0.5 * (t0 + t1)
            cm = evaluate(a[li] + tm[:, None] * (b - a)[li])
            evaluations += cm.size
            for k in range(len(li)):
                if cm[k] < sampled_min[li[k]]:
                    sampled_min[li[k]], worst_tau[li[k]] = cm[k], tm[k]
            li = np.concatenate([li, li])
            t0, t1 = np.concatenate([t0, tm]), np.concatenate([tm, t1])
            c0, c1 = np.concatenate([c0, cm]), np.concatenate([cm, c1])
            lbi = 0.5 * (c0 + c1) - 0.5 * lam[li] * (t1 - t0)
            refine = (lbi < required) & (np.minimum(c0, c1) >= required)
            done = ~refine if depth < max_depth - 1 else np.ones_like(refine)
            for k in np.flatnonzero(done):
                bound[li[k]] = min(bound[li[k]], lbi[k])
            if done.all():
                break
            li, t0, t1, c0, c1 = li[refine], t0[refine], t1[refine], c0[refine], c1[refine]
    bound = np.minimum(bound, sampled_min)
    return LineCertificate(bound, sampled_min, worst_tau, clr[:, -1].copy(), evaluations)
