"""Start configurations for the extensible arm's tip IK (:mod:`core.kinematics.delta_ik`).

Structured guesses (the single constant-curvature arc through the target, arcs after straight
proximal segments, straight postures) and a fixed low-discrepancy set over the rack box. The
solver moves every start into the feasible set (rack box and bending limit) before iterating.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import numpy.typing as npt

from core.kinematics import delta as dk
from core.kinematics.delta_ik_iteration import Problem

Array = npt.NDArray[np.float64]


def arc_seed(pb: Problem, rel: Array, n_arc: int) -> Array:
    """Deltas (n_arc, 3) bending one constant-curvature arc from the origin through ``rel``."""
    x, y, z = rel
    r = math.hypot(x, y)
    az = math.atan2(y, x)
    big_theta = 2.0 * math.atan2(r, z)  # total bend of the arc, [0, 2 pi]
    chord = math.hypot(r, z)
    half = 0.5 * big_theta
    s = chord if half < 1e-6 else chord * half / max(math.sin(half), 1e-3)
    theta_i, len_i = big_theta / n_arc, s / n_arc
    seg = np.array([theta_i * pb.d * math.cos(az), theta_i * pb.d * math.sin(az), len_i - pb.L0])
    return np.tile(seg, (n_arc, 1))


@functools.lru_cache(maxsize=16)
def halton(count: int, dim: int) -> Array:
    """First ``count`` points (skipping 0) of the Halton sequence in [0, 1)^dim (deterministic;
    cached, so read-only: callers must not modify it)."""
    primes = [2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37, 41, 43, 47, 53, 59, 61]
    if dim > len(primes):  # more than 6 segments: a fixed pseudo-random set instead
        out = np.random.default_rng(dim).uniform(size=(count, dim))
        out.flags.writeable = False
        return out
    out = np.zeros((count, dim))
    for k in range(count):
        for j in range(dim):
            f, i, x = 1.0, k + 1, 0.0
            while i:
                f /= primes[j]
                x += f * (i % primes[j])
                i //= primes[j]
            out[k, j] = x
    out.flags.writeable = False
    return out


def seeds(pb: Problem, restart_seeds: int) -> Array:
    """Restart seeds as rack lengths (K, 3n)."""
    n = pb.n
    deltas = [arc_seed(pb, pb.target, n)]
    straight = np.zeros((n, 3))
    for frac in (0.25, 0.75):
        # Proximal segments straight at a fraction of their range, the rest as one arc.
        for k in range(1, n):
            head = np.zeros((k, 3))
            head[:, 2] = pb.lo + frac * (pb.hi - pb.lo) - pb.L0
            rel = pb.target - np.array([0.0, 0.0, k * (pb.lo + frac * (pb.hi - pb.lo))])
            deltas.append(np.vstack([head, arc_seed(pb, rel, n - k)]))
    for frac in (0.0, 0.5):
        straight[:, 2] = pb.lo + frac * (pb.hi - pb.lo) - pb.L0
        deltas.append(straight.copy())
    L = dk.actuators_from_delta(np.stack(deltas), pb.phi, pb.L0).reshape(len(deltas), 3 * n)
    if restart_seeds:
        L = np.vstack([L, pb.lo + (pb.hi - pb.lo) * halton(restart_seeds, 3 * n)])
    return L
