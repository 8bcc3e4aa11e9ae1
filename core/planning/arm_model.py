"""Planar PCC arm model with exact first and second derivatives, for the grasp planner's solver.

The planner's hot loop needs, for a point rigidly attached to the tip frame, its position, the
Jacobian and the Hessian with respect to the curvatures, batched and with as few numpy calls as
possible. Positions are complex numbers ``x + i y``. Segment ``j`` contributes its chord

    T_j = c_j(kappa_j) E_j,   c_j = L_j sinc(kappa_j L_j / 2),   E_j = exp(i mid_j),

where ``mid_j = theta_0 + sum_{k<j} kappa_k L_k + kappa_j L_j / 2`` is linear in kappa (this is
the paper's ``forwKin`` in a form that is exact at kappa = 0, the same as
:mod:`core.kinematics.planar`). A tip-frame offset ``o = along + i left`` adds
``o exp(i theta_N)``. With ``M_j`` the midpoint of chord ``j`` (relative to the base) and
``V_j = q - M_j``, the Jacobian is ``J_j = c'_j E_j + i L_j V_j`` and the Hessian follows by
differentiating once more (see :meth:`ArmModel.point`).
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]
CArray = npt.NDArray[np.complex128]


def sinc_derivs(u: Array) -> tuple[Array, Array, Array]:
    """sin(u)/u and its first two derivatives, with series where the closed forms cancel."""
    sn, cn = np.sin(u), np.cos(u)
    small = np.abs(u) < 2e-2
    if small.any():
        us = np.where(small, 1.0, u)
        s0 = np.where(small, 1.0 - u * u / 6.0 + u**4 / 120.0, sn / us)
        s1 = np.where(small, u * (-1.0 / 3.0 + u * u / 30.0 - u**4 / 840.0),
                      (us * cn - sn) / (us * us))
        s2 = np.where(small, -1.0 / 3.0 + u * u / 10.0 - u**4 / 168.0, -s0 - 2.0 * s1 / us)
        return s0, s1, s2
    s0 = sn / u
    s1 = (u * cn - sn) / (u * u)
    return s0, s1, -s0 - 2.0 * s1 / u


class _PyConsts(NamedTuple):
    """Model constants as Python lists, for the solver's scalar kernel."""

    n: int
    L: list
    c1: list
    c2: list
    iL: list
    L2q: list
    LL: list
    lo: list
    hi: list


@dataclasses.dataclass(frozen=True, eq=False)
class ArmModel:
    """Geometry of a planar PCC arm plus precomputed constants for the derivative formulas.

    Attributes:
        lengths: Segment lengths, (N,).
        base: Base position as a complex number.
        theta0: Base heading (rad).
        lo, hi: Curvature bounds, (N,).
        half_width: Half-width of the arm body (m), for clearance.
    """

    lengths: Array
    base: complex
    theta0: float
    lo: Array
    hi: Array
    half_width: float

    def __post_init__(self) -> None:
        n = self.n
        strict = np.tri(n, n, -1)  # [k < j] at (j, k)
        L = self.lengths
        set_ = object.__setattr__
        set_(self, "_iL", 1j * L)
        set_(self, "_c1", L * L * 0.5)
        set_(self, "_c2", L * L * L * 0.25)
        set_(self, "_iA", 1j * (strict * L[None, :] + np.diag(0.5 * L)))
        set_(self, "_lower_half", strict + 0.5 * np.eye(n))
        set_(self, "_iLstrict", 1j * strict * L[None, :])
        set_(self, "_iLcol", 1j * L[:, None])
        set_(self, "_strict", strict)
        set_(self, "_eye", np.eye(n, dtype=bool))
        set_(self, "_iL4", 0.25j * L)
        set_(self, "py", _PyConsts(
            n, L.tolist(), (0.5 * L * L).tolist(), (0.25 * L**3).tolist(), (1j * L).tolist(),
            (0.25 * L * L).tolist(), np.multiply.outer(L, L).tolist(), self.lo.tolist(),
            self.hi.tolist()))
        # The same constants as arrays, for the compiled solver (core.planning.solver_jit).
        set_(self, "jit_consts", (L.astype(float), 0.5 * L * L, 0.25 * L**3,
                                  np.multiply.outer(L, L), 0.25 * L * L, self.lo.astype(float),
                                  self.hi.astype(float),
                                  complex(math.cos(self.theta0), math.sin(self.theta0))))
        # Arc length from the start of segment k to the end of the arm (Lipschitz bounds).
        set_(self, "_downstream", np.cumsum(L[::-1])[::-1].copy())

    @property
    def n(self) -> int:
        return int(self.lengths.shape[0])

    @classmethod
    def from_robot(cls, robot) -> "ArmModel":
        """Model of a :class:`core.robots.SoftArm`."""
        lo, hi = robot.kappa_limits
        bx, by, bth = (float(v) for v in robot.base_pose)
        return cls(np.asarray(robot.lengths, float), complex(bx, by), bth,
                   np.asarray(lo, float), np.asarray(hi, float), float(robot.half_width))

    # ---------------------------------------------------------------- kinematics

    def frames(self, kappa: Array) -> tuple[CArray, Array]:
        """Segment end points (complex, (..., N+1)) and headings (..., N+1), base first."""
        kappa = np.asarray(kappa, float)
        t = kappa * self.lengths
        u = 0.5 * t
        th = np.empty(kappa.shape[:-1] + (self.n + 1,))
        th[..., 0] = self.theta0
        np.cumsum(t, axis=-1, out=th[..., 1:])
        th[..., 1:] += self.theta0
        # sin(u)/u, exact at 0 (numpy's sinc is sin(pi x)/(pi x)).
        T = (self.lengths * np.sinc(u * (1.0 / np.pi))) * np.exp(1j * (th[..., 1:] - u))
        pts = np.empty(kappa.shape[:-1] + (self.n + 1,), complex)
        pts[..., 0] = self.base
        np.cumsum(T, axis=-1, out=pts[..., 1:])
        pts[..., 1:] += self.base
        return pts, th

    def point_py(self, kappa, offset: complex = 0j) -> tuple[complex, float]:
        """One tip-frame point and the tip heading, with Python scalars (fast for one config)."""
        c = self.py
        th, p = self.theta0, self.base
        sin, cos = math.sin, math.cos
        for k, L in zip(kappa, c.L):
            u = 0.5 * k * L
            s0 = sin(u) / u if u != 0.0 else 1.0
            mid = th + u
            p += (L * s0) * complex(cos(mid), sin(mid))
            th = mid + u
        return p + offset * complex(cos(th), sin(th)), th

    def clearance_py(self, kappa, center: complex, radius: float) -> float:
        """:meth:`body_clearance` of one configuration with Python scalars."""
        c = self.py
        th, p = self.theta0, self.base
        sin, cos, atan2, sqrt = math.sin, math.cos, math.atan2, math.sqrt
        best = abs(center - p)
        for k, L in zip(kappa, c.L):
            u = 0.5 * k * L
            s0 = sin(u) / u if u != 0.0 else 1.0
            rel = (center - p) * complex(cos(th), -sin(th))
            a, lft = rel.real, rel.imag
            if k < 0.0:
                k, lft = -k, -lft
            k += 1e-12
            s_star = atan2(k * a, 1.0 - k * lft) / k
            if 0.0 <= s_star <= L:
                d = abs(k * (a * a + lft * lft) - 2.0 * lft) / (
                    sqrt((k * a) ** 2 + (1.0 - k * lft) ** 2) + 1.0)
                best = min(best, d)
            mid = th + u
            p += (L * s0) * complex(cos(mid), sin(mid))
            th = mid + u
            best = min(best, abs(center - p))
        return best - self.half_width - radius

    def point(self, kappa: Array, offset: complex | CArray, hessian: bool = True):
        """A point rigidly attached to the tip frame, with exact derivatives.

        Args:
            kappa: (B, N) curvatures.
            offset: Tip-frame offset ``along + i left`` (scalar or (B,)).
            hessian: Also return the (B, N, N) complex Hessian.

        Returns:
            ``(q, theta, J, H)``: q (B,) complex position, theta (B,) tip heading,
            J (B, N) complex d q / d kappa, H (B, N, N) complex (or None).
        """
        t = kappa * self.lengths
        u = 0.5 * t
        th_end = np.cumsum(t, axis=-1)
        th_end += self.theta0
        s0, s1, s2 = sinc_derivs(u)
        E = np.exp(1j * (th_end - u))
        T = (self.lengths * s0) * E
        Tcum = np.cumsum(T, axis=-1)
        theta = th_end[:, -1]
        q_rel = Tcum[:, -1] + offset * np.exp(1j * theta)
        M = Tcum - 0.5 * T
        V = q_rel[:, None] - M
        D1 = (self._c1 * s1) * E
        J = D1 + self._iL * V
        if not hessian:
            return q_rel + self.base, theta, J, None
        # dV_j/dk_k = J_k - ([k<j] + d_jk/2) D1_k - i [k<j] L_k (M_j - M_k) - i d_jk L_j T_j / 4
        dV = J[:, None, :] - self._lower_half * D1[:, None, :]
        dV -= self._iLstrict * (M[:, :, None] - M[:, None, :])
        H = self._iLcol * dV
        H += self._iA * D1[:, :, None]
        diag = (self._c2 * s2) * E - self._iL * self._iL4 * T
        H[:, self._eye] += diag
        return q_rel + self.base, theta, J, H

    # ---------------------------------------------------------------- clearance

    def arc_distances(self, kappa: Array, c: complex | CArray,
                      with_s: bool = True) -> tuple[Array, Array | None]:
        """Exact distance from point ``c`` to each segment's backbone arc.

        For a constant-curvature arc the closest point to ``c`` is either where the ray from the
        arc's centre through ``c`` meets the arc, or an end point. Written in the segment's start
        frame, mirrored so the arc turns left, and with |kappa| + 1e-12 so that the same formulas
        are exact (no cancellation, no 0/0) down to kappa = 0.

        Args:
            kappa: (..., N) curvatures.
            c: Point(s), complex, broadcastable to kappa's leading shape.
            with_s: Also return the arc length of each closest point.

        Returns:
            ``(dist, s_star)``: (..., N) distances and arc lengths (None if not ``with_s``).
        """
        kappa = np.asarray(kappa, float)
        pts, th = self.frames(kappa)
        c = np.asarray(c)[..., None]
        rel = c - pts
        d_pts = np.abs(rel)
        rel = rel[..., :-1] * np.exp(-1j * th[..., :-1])
        a = rel.real
        lft = np.where(kappa < 0.0, -rel.imag, rel.imag)
        k = np.abs(kappa) + 1e-12
        ka = k * a
        one_kl = 1.0 - k * lft
        s_star = np.arctan2(ka, one_kl) / k
        inside = (s_star >= 0.0) & (s_star <= self.lengths)
        d_circle = np.abs(ka * a + lft * (k * lft - 2.0)) / (np.sqrt(ka * ka + one_kl * one_kl)
                                                              + 1.0)
        d_start, d_end = d_pts[..., :-1], d_pts[..., 1:]
        d_ends = np.minimum(d_start, d_end)
        on_arc = inside & (d_circle < d_ends)
        dist = np.where(on_arc, d_circle, d_ends)
        if not with_s:
            return dist, None
        s_out = np.where(on_arc, s_star, np.where(d_start <= d_end, 0.0, self.lengths))
        return dist, s_out

    def body_clearance(self, kappa: Array, center: complex, radius: float) -> Array:
        """Distance from the arm body (backbone +- half_width) to the disk edge, (...,).

        The same closest-point formulas as :meth:`arc_distances`, fused for one point and
        reduced to the minimum (about half the numpy calls): arcs whose foot point falls outside
        them contribute only their end points, which are all checked anyway.
        """
        kappa = np.asarray(kappa, float)
        t = kappa * self.lengths
        u = 0.5 * t
        th_end = np.cumsum(t, axis=-1)
        th_end += self.theta0
        e_start = np.exp(1j * (th_end - t))
        s0 = np.sin(u)
        np.divide(s0, u, out=s0, where=u != 0.0)
        s0[u == 0.0] = 1.0
        chord = (self.lengths * s0) * e_start * np.exp(1j * u)
        rel_end = (center - self.base) - np.cumsum(chord, axis=-1)     # c - segment ends
        rel = (rel_end + chord) * np.conj(e_start)                      # c - start, start frame
        a = rel.real
        lft = rel.imag
        # Signed curvature instead of mirroring each arc to turn left: with ks = kappa +-
        # 1e-12 (away from 0) and k = |ks|, the mirrored formulas read k a, ks lft and
        # |ks a^2 + lft (ks lft - 2)| (the same values, fewer array passes).
        ks = kappa + np.copysign(1e-12, kappa)
        k = np.abs(ks)
        ka = k * a
        kl = ks * lft
        one_kl = 1.0 - kl
        s_star = np.arctan2(ka, one_kl)
        inside = (s_star >= 0.0) & (s_star <= k * self.lengths)
        d_circle = np.abs(ks * (a * a) + lft * (kl - 2.0)) / (np.hypot(ka, one_kl) + 1.0)
        d = np.minimum(np.where(inside, d_circle, np.inf).min(axis=-1),
                       np.abs(rel_end).min(axis=-1))
        return np.minimum(d, abs(center - self.base)) - (self.half_width + radius)

    def arc_points(self, kappa: Array, s: Array) -> tuple[CArray, CArray]:
        """Points at arc length ``s[b, j]`` along each segment j and their Jacobians.

        Args:
            kappa: (B, N).
            s: (B, N) arc lengths within each segment.

        Returns:
            ``(p, J)``: p (B, N) complex points, J (B, N, N) complex with J[b, j, k] = dp_j/dkappa_k.
        """
        L = self.lengths
        t = kappa * L
        u = 0.5 * t
        th_end = np.cumsum(t, axis=-1) + self.theta0
        th_start = th_end - t
        s0, s1, _ = sinc_derivs(u)
        E = np.exp(1j * (th_end - u))
        T = (L * s0) * E
        Tcum = np.cumsum(T, axis=-1)
        start = Tcum - T
        up = 0.5 * kappa * s
        p0, p1, _ = sinc_derivs(up)
        Ep = np.exp(1j * (th_start + up))
        partial = s * p0 * Ep
        p_rel = start + partial
        D1 = (self._c1 * s1) * E
        # Upstream segments k < j: c'_k E_k + i L_k (p_j - M_k).
        M = Tcum - 0.5 * T
        Jm = (D1[:, None, :] + self._iL[None, None, :] * (p_rel[:, :, None] - M[:, None, :]))
        Jm = Jm * np.tri(self.n, self.n, -1)[None]
        own = 0.5 * s * s * p1 * Ep + 0.5j * s * partial
        Jm[:, self._eye] = own
        return p_rel + self.base, Jm

    def displacement_bound(self, dkappa: Array) -> Array:
        """Upper bound on how far any backbone point moves for a curvature change ``dkappa``.

        Bending segment k by dkappa_k moves a point at arc distance sigma downstream of the
        segment's start by at most |dkappa_k| L_k sigma, so sum_k |dkappa_k| L_k (length from
        segment k's start to the tip) bounds every backbone point's displacement.
        """
        return np.abs(dkappa) @ (self.lengths * self._downstream)


def wrap(angle: Array | float) -> Array | float:
    """Wrap angles to (-pi, pi]."""
    return np.pi - np.mod(np.pi - np.asarray(angle), 2.0 * np.pi) if np.ndim(angle) else (
        math.pi - (math.pi - angle) % (2.0 * math.pi))
