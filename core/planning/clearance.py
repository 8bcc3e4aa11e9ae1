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
import math
from collections.abc import Callable
from operator import add

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
    heading = complex(math.cos(th), math.sin(th))
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


def certify_lines(model: ArmModel, starts: Array, ends: Array, center: complex, radius: float,
                  required: float = 0.0, samples: int = 8) -> LineCertificate:
    """Lower-bound the body clearance to the object disk (``center``, ``radius``) along straight
    lines in kappa: :func:`certify_function` with :meth:`ArmModel.body_clearance` and its rate
    :meth:`ArmModel.displacement_bound` (its ``max_depth`` and ``slack`` defaults).

    Args:
        model: Arm model.
        starts, ends, required, samples: as :func:`certify_function`.
        center, radius: Object disk.

    Returns:
        :class:`LineCertificate`.
    """
    a = np.asarray(starts, float)
    b = np.asarray(ends, float)
    return certify_function(lambda k: model.body_clearance(k, center, radius),
                            model.displacement_bound(b - a), a, b, required, samples)


def certify_function(evaluate: Callable[[Array], Array], lam: Array, starts: Array, ends: Array,
                     required: float = 0.0, samples: int = 8, max_depth: int = 8,
                     slack: float = 0.005) -> LineCertificate:
    """Lower-bound any clearance along straight lines in kappa, given its Lipschitz rate.

    Args:
        evaluate: (..., N) configurations -> (...,) clearance (m), exact at each configuration.
        lam: (n,) bound on how fast the clearance can change per unit tau along each line
            (m), e.g. :meth:`ArmModel.displacement_bound`.
        starts, ends: (n, N) line end configurations.
        required: Clearance the caller needs; intervals whose bound is already >= this are
            not refined further.
        samples: Least initial number of intervals per line.
        max_depth: Maximum number of bisection rounds.
        slack: Target Lipschitz slack of the initial sampling (m); more samples are taken (up
            to 64) on lines whose configurations move a lot.

    Returns:
        :class:`LineCertificate`.
    """
    a = np.asarray(starts, float)
    b = np.asarray(ends, float)
    span = b - a
    lam = np.asarray(lam, float).tolist()                          # (n,) per unit tau
    # Per line, enough intervals S that the Lipschitz slack Lambda / (2 S) stays below `slack`,
    # so that usually one batched evaluation (ends included) settles every line and no
    # bisection is needed. The bookkeeping is in Python lists: a few lines of a few dozen
    # samples each, where numpy calls would cost more than the arithmetic.
    counts, taus, lines = [], [], []
    for i, lm in enumerate(lam):
        s_i = min(max(samples, math.ceil(lm / (2.0 * slack))), 64)
        counts.append(s_i)
        taus += [k / s_i for k in range(s_i + 1)]
        lines += [i] * (s_i + 1)
    li = np.array(lines, dtype=np.intp)
    clr = evaluate(a[li] + np.array(taus)[:, None] * span[li]).tolist()
    evaluations = len(clr)
    bound, sampled_min, worst_tau = [], [], []
    todo = []                       # (line, t0, t1, c0, c1) intervals to bisect
    pos = 0
    end_clearance = []
    for i, s_i in enumerate(counts):
        vals = clr[pos:pos + s_i + 1]
        pos += s_i + 1
        end_clearance.append(vals[-1])
        v_min = min(vals)
        sampled_min.append(v_min)
        worst_tau.append(vals.index(v_min) / s_i)
        half = 0.5 * lam[i] / s_i
        # The bound is monotone in c0 + c1, so the smallest pair sum gives the line's bound
        # (the same rounding as interval by interval); only a line whose bound falls short
        # of `required` is gone through interval by interval for bisection.
        best = 0.5 * min(map(add, vals, vals[1:])) - half
        if best >= required:
            bound.append(best)
            continue
        best = math.inf
        for k in range(s_i):
            c0, c1 = vals[k], vals[k + 1]
            lb = 0.5 * (c0 + c1) - half
            if lb < required and min(c0, c1) >= required:
                todo.append((i, k / s_i, (k + 1) / s_i, c0, c1))
            elif lb < best:
                best = lb
        bound.append(best)
    for depth in range(max_depth):
        if not todo:
            break
        li = np.array([t[0] for t in todo], dtype=np.intp)
        tm = [0.5 * (t[1] + t[2]) for t in todo]
        cm = evaluate(a[li] + np.array(tm)[:, None] * span[li]).tolist()
        evaluations += len(cm)
        nxt = []
        for (i, t0, t1, c0, c1), t_mid, c_mid in zip(todo, tm, cm):
            if c_mid < sampled_min[i]:
                sampled_min[i], worst_tau[i] = c_mid, t_mid
            half = 0.25 * lam[i] * (t1 - t0)
            for u0, u1, v0, v1 in ((t0, t_mid, c0, c_mid), (t_mid, t1, c_mid, c1)):
                lb = 0.5 * (v0 + v1) - half
                if lb < required and min(v0, v1) >= required and depth < max_depth - 1:
                    nxt.append((i, u0, u1, v0, v1))
                elif lb < bound[i]:
                    bound[i] = lb
        todo = nxt
    bound = np.minimum(np.array(bound), sampled_min)
    return LineCertificate(bound, np.array(sampled_min), np.array(worst_tau),
                           np.array(end_clearance), evaluations)
