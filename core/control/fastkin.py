"""Scalar (math-module) forward kinematics and marker fit for the 100 Hz path.

:func:`core.kinematics.planar.forward_kinematics` and :func:`~core.kinematics.planar.fit_arm`
are batched numpy code; for one arm of six segments their per-call overhead (~70 / ~300 us)
dominates the control period. These are the same formulas on Python floats (tested equal to
the numpy versions), a few microseconds per call.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]


def fk(kappa: Sequence[float], lengths: Sequence[float], base: Sequence[float]) -> Array:
    """Poses [x, y, theta] at the base and every segment end, shape (N+1, 3)."""
    x, y, th = float(base[0]), float(base[1]), float(base[2])
    out = [(x, y, th)]
    ks = kappa.tolist() if isinstance(kappa, np.ndarray) else kappa
    ls = lengths.tolist() if isinstance(lengths, np.ndarray) else lengths
    for k, ln in zip(ks, ls):
        half = 0.5 * k * ln
        chord = ln * (math.sin(half) / half if half != 0.0 else 1.0)
        mid = th + half
        x += chord * math.cos(mid)
        y += chord * math.sin(mid)
        th += 2.0 * half
        out.append((x, y, th))
    return np.array(out)


def fit(markers: Array, base: Sequence[float]) -> tuple[Array, Array]:
    """The paper's recursive ``singleSegInvKin`` over segment-end markers (N, 2).

    Returns:
        ``(kappa, lengths)`` each (N,), equal to :func:`core.kinematics.planar.fit_arm`.
    """
    x, y, th = float(base[0]), float(base[1]), float(base[2])
    n = len(markers)
    kappa = np.empty(n)
    length = np.empty(n)
    for i, (mx, my) in enumerate(markers.tolist()):
        dx, dy = mx - x, my - y
        c, s = math.cos(th), math.sin(th)
        along = c * dx + s * dy
        left = -s * dx + c * dy
        chord2 = along * along + left * left
        chord = math.sqrt(chord2)
        gamma = math.atan2(left, along)
        k = 2.0 * left / chord2 if chord2 > 0 else 0.0
        if abs(gamma) < 0.5 * math.pi:
            ln = chord * (gamma / math.sin(gamma) if gamma != 0.0 else 1.0)
        else:
            ln = gamma * chord2 / left if left != 0.0 else 0.0
        kappa[i], length[i] = k, ln
        x, y, th = mx, my, th + k * ln
    return kappa, length


def point_in_pose(pose: Sequence[float], along: float, left: float) -> tuple[float, float]:
    """A point at (along, left) in the frame of ``pose``."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return pose[0] + along * c - left * s, pose[1] + along * s + left * c
