"""Obstacles on the table for the planar arm: what the whole arm, gripper included, must avoid.

An obstacle is a disk (x, y, r) on the table (the enclosing cylinder of whatever stands there).
Unlike the object, nothing may come near it: every point of the arm body (the backbone swept by
its half-width) and of the gripper (a straight stadium of the robot file's gripper length and
half-width, rooted at the tip) must stay at least ``clearance`` from every obstacle disk, at the
waypoints and along the straight lines in kappa that the curvature controller follows between
them.

* :func:`obstacle_clearance` -- exact distance at given configurations, per obstacle.
* :func:`certify_obstacle_lines` -- a guaranteed lower bound along straight lines in kappa
  (:func:`core.planning.clearance.certify_function`): no point of the body or the gripper moves
  faster than sum_k |dkappa_k| L_k (arc length from segment k to the tip + gripper length) per
  unit tau, so the clearance is Lipschitz with that rate.
* :class:`ObstacleConstraints` -- the same distances as inequality rows of the grasp SQP
  (:mod:`core.planning.grasp_solver`'s constraint-set protocol): one row per segment arc and one
  for the gripper, per obstacle.
* :func:`check_obstacles` -- refuse bad obstacles (not finite, radius not positive, on the
  arm's base) with a message for the operator.
* :func:`with_other_objects` -- the obstacles plus every other object on the table: a plan
  for one object keeps the clearance from the objects it does not grasp too (the console, the
  planner CLI's ``--other``, a row of objects and the trials).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from core.planning.arm_model import ArmModel
from core.planning.clearance import certify_function

Array = npt.NDArray[np.float64]

MAX_RADIUS = 0.5        # m, an obstacle larger than this is not something on a table
MAX_CLEARANCE = 0.2     # m, largest clearance the planner accepts
_INACTIVE = 10.0        # m added to a row that another row already covers
NEAR_TOL = 1e-5         # m: a solve this close to its constraints is taken (paper: 2e-3)
DEFAULT_CLEARANCE = 0.010   # m, the clearance of the planner CLI and the trials (as the console)


@dataclasses.dataclass(frozen=True)
class Obstacle:
    """A cylinder on the table the arm must keep clear of (metres)."""

    name: str
    x: float
    y: float
    r: float

    @property
    def center(self) -> complex:
        return complex(self.x, self.y)


@dataclasses.dataclass(frozen=True)
class GripperShape:
    """The straight gripper as the obstacle checks see it: length and half-width (m)."""

    length: float
    half_width: float

    @classmethod
    def from_robot(cls, robot) -> "GripperShape":
        return cls(float(robot.gripper.length), float(robot.gripper.half_width))


def _mm(v: float) -> str:
    return f"{v * 1e3:.0f} mm"


def check_obstacle(obs: Obstacle, model: ArmModel, base_keepout: float = 0.03) -> Obstacle:
    """Raise ValueError with an operator message if ``obs`` is not a sensible obstacle."""
    if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in (obs.x, obs.y, obs.r)):
        raise ValueError(f"{obs.name}: position and radius must be finite numbers")
    if not 0.0 < obs.r <= MAX_RADIUS:
        raise ValueError(f"{obs.name}: the radius must be positive and at most "
                         f"{_mm(MAX_RADIUS)}, got {obs.r * 1e3:.1f} mm")
    if max(abs(obs.x), abs(obs.y)) > 2.0:
        raise ValueError(f"{obs.name}: an obstacle must lie on the table (within 2 m of the "
                         f"base)")
    dist = abs(obs.center - model.base)
    need = obs.r + model.half_width + base_keepout
    if dist < need:
        raise ValueError(f"{obs.name} is on the arm's base ({_mm(dist)} from it); place it at "
                         f"least {_mm(need)} away")
    return obs


def check_clearance(clearance: float) -> float:
    """The planner's obstacle clearance (m), or ValueError."""
    c = float(clearance)
    if not (math.isfinite(c) and 0.0 <= c <= MAX_CLEARANCE):
        raise ValueError(f"the obstacle clearance must be between 0 and {_mm(MAX_CLEARANCE)}, "
                         f"got {c * 1e3:g} mm")
    return c


def first_overlap(x: float, y: float, r: float, disks: Sequence) -> tuple[object, float] | None:
    """The first of ``disks`` (anything with ``x``, ``y``, ``r``: obstacles, table objects) that
    a disk of radius ``r`` centred at ``(x, y)`` overlaps, and the gap between them (negative,
    m); None when it is clear of them all (touching is clear)."""
    for d in disks:
        gap = math.hypot(d.x - x, d.y - y) - d.r - r
        if gap < 0.0:
            return d, gap
    return None


def with_other_objects(obstacles: Sequence[Obstacle],
                       others: Sequence[Any]) -> tuple[Obstacle, ...]:
    """The disks a plan for one object keeps its clearance from: ``obstacles`` and then every
    other object on the table, each an obstacle disk of its own radius.

    Args:
        obstacles: The obstacles placed on the table.
        others: The objects other than the one being grasped: anything with ``x``, ``y`` and
            ``r`` (m) and optionally a ``name`` (a table object's; else "Object k", k counting
            ``others`` from 1). A name an obstacle already has gets " (object)" appended, so
            the names stay unique (a refusal names the one in the way).

    Returns:
        The obstacles followed by the other objects, as :class:`Obstacle`.
    """
    out = list(obstacles)
    names = {o.name for o in out}
    for k, obj in enumerate(others, 1):
        name = str(getattr(obj, "name", None) or f"Object {k}")
        while name in names:
            name += " (object)"
        names.add(name)
        out.append(Obstacle(name, float(obj.x), float(obj.y), float(obj.r)))
    return tuple(out)


def check_obstacles(obstacles: Sequence[Obstacle], model: ArmModel,
                    base_keepout: float = 0.03) -> tuple[Obstacle, ...]:
    """Validate every obstacle (ValueError names the first bad one); names must be unique."""
    names = [o.name for o in obstacles]
    if len(set(names)) != len(names):
        raise ValueError("obstacle names must be unique")
    return tuple(check_obstacle(o, model, base_keepout) for o in obstacles)


def _gripper_points(model: ArmModel, kappas: Array) -> tuple[Array, Array]:
    """Gripper root (tip point, complex) and heading exp(i theta) of configurations (...)."""
    pts, th = model.frames(kappas)
    return pts[..., -1], np.exp(1j * th[..., -1])


def _segment_distance(root: Array, heading: Array, length: float, center: complex) -> Array:
    along = np.clip(((center - root) * np.conj(heading)).real, 0.0, length)
    return np.abs(center - (root + heading * along))


def obstacle_clearance(model: ArmModel, kappas: npt.ArrayLike, obstacles: Sequence[Obstacle],
                       gripper: GripperShape) -> Array:
    """Exact gap between the arm (body and gripper) and each obstacle disk.

    Args:
        kappas: (..., N) configurations.

    Returns:
        (..., K) gaps in metres, one per obstacle; negative means overlap.
    """
    k = np.asarray(kappas, float)
    root, heading = _gripper_points(model, k)
    out = np.empty(k.shape[:-1] + (len(obstacles),))
    for j, o in enumerate(obstacles):
        body = model.body_clearance(k, o.center, o.r)
        grip = _segment_distance(root, heading, gripper.length, o.center) - gripper.half_width \
            - o.r
        out[..., j] = np.minimum(body, grip)
    return out


def line_rate(model: ArmModel, dkappa: Array, gripper: GripperShape) -> Array:
    """Upper bound on how far any arm or gripper point moves per unit tau along dkappa (n,)."""
    L = model.lengths
    downstream = np.cumsum(L[::-1])[::-1] + gripper.length
    return np.abs(np.asarray(dkappa, float)) @ (L * downstream)


@dataclasses.dataclass(frozen=True)
class ObstacleCertificate:
    """Clearance to each obstacle along straight lines in kappa.

    Attributes:
        lower_bound: (n, K) guaranteed lower bound along each line, per obstacle (m).
        worst_tau: (n, K) where on the line the smallest sampled gap was.
    """

    lower_bound: Array
    worst_tau: Array

    def line_bound(self) -> Array:
        """(n,) lower bound to the nearest obstacle along each line (inf without obstacles)."""
        return self.lower_bound.min(axis=1, initial=np.inf)


def certify_obstacle_lines(model: ArmModel, starts: npt.ArrayLike, ends: npt.ArrayLike,
                           obstacles: Sequence[Obstacle], gripper: GripperShape,
                           required: float = 0.0, samples: int = 8) -> ObstacleCertificate:
    """Guaranteed lower bounds of the arm-and-gripper gap to each obstacle along the lines
    kappa(tau) = a + tau (b - a), tau in [0, 1] (see the module docstring)."""
    a = np.atleast_2d(np.asarray(starts, float))
    b = np.atleast_2d(np.asarray(ends, float))
    lam = line_rate(model, b - a, gripper)
    lb = np.full((a.shape[0], len(obstacles)), np.inf)
    worst = np.zeros_like(lb)
    for j, o in enumerate(obstacles):
        cert = certify_function(lambda k, o=o: obstacle_clearance(model, k, (o,), gripper)[..., 0],
                                lam, a, b, required, samples)
        lb[:, j], worst[:, j] = cert.lower_bound, cert.worst_tau
    return ObstacleCertificate(lb, worst)


@dataclasses.dataclass(frozen=True)
class ObstacleConstraints:
    """Obstacle disks as rows h(kappa) >= 0 of the grasp SQP (grasp_solver's protocol).

    Per obstacle: one row per segment (its arc's distance to the centre minus r + half-width +
    clearance) and one for the gripper (the straight gripper's distance minus r + gripper
    half-width + clearance).
    """

    centers: tuple[complex, ...]
    rho_body: tuple[float, ...]
    rho_grip: tuple[float, ...]
    grip_length: float

    @classmethod
    def build(cls, model: ArmModel, obstacles: Sequence[Obstacle], gripper: GripperShape,
              clearance: float) -> "ObstacleConstraints | None":
        if not obstacles:
            return None
        return cls(tuple(o.center for o in obstacles),
                   tuple(o.r + model.half_width + clearance for o in obstacles),
                   tuple(o.r + gripper.half_width + clearance for o in obstacles),
                   gripper.length)

    def size(self, n: int) -> int:
        return (n + 1) * len(self.centers)

    def evaluate(self, model: ArmModel, x: list[float]) -> tuple[Array, tuple[Array, Array]]:
        """Row values and the closest points' arc lengths (per obstacle and segment) and
        gripper positions. Python scalars: with N = 6 this is several times faster than the
        batched :meth:`ArmModel.arc_distances` it matches (``tests/core/test_obstacles.py``)."""
        sin, cos, atan2, sqrt = math.sin, math.cos, math.atan2, math.sqrt
        th, p = model.theta0, model.base
        starts, heads = [], []
        for k, L in zip(x, model.py.L):
            starts.append(p)
            heads.append(th)
            u = 0.5 * k * L
            s0 = sin(u) / u if u != 0.0 else 1.0
            mid = th + u
            p += (L * s0) * complex(cos(mid), sin(mid))
            th = mid + u
        tip, heading = p, complex(cos(th), sin(th))
        ends = starts[1:] + [tip]
        rot = [complex(cos(t), -sin(t)) for t in heads]
        h, sstar, along = [], [], []
        for c, rb, rg in zip(self.centers, self.rho_body, self.rho_grip):
            srow = []
            for k, L, p0, p1, r in zip(x, model.py.L, starts, ends, rot):
                rel = (c - p0) * r
                a, lft = rel.real, rel.imag
                if k < 0.0:
                    k, lft = -k, -lft
                k += 1e-12
                d0, d1 = abs(c - p0), abs(c - p1)
                d, s = (d0, 0.0) if d0 <= d1 else (d1, L)
                s_star = atan2(k * a, 1.0 - k * lft) / k
                if 0.0 <= s_star <= L:
                    dc = abs(k * a * a + lft * (k * lft - 2.0)) / (
                        sqrt((k * a) ** 2 + (1.0 - k * lft) ** 2) + 1.0)
                    if dc < d:
                        d, s = dc, s_star
                # A closest point at a segment's start is the previous segment's end (or the
                # fixed base), already a row: a duplicate (or zero) row makes the SQP's KKT
                # system singular, so it is kept inactive.
                h.append(d - rb if s > 0.0 else d - rb + _INACTIVE)
                srow.append(s)
            sstar.append(srow)
            t = ((c - tip) * heading.conjugate()).real
            t = min(max(t, 0.0), self.grip_length)
            along.append(t)
            h.append(abs(c - (tip + heading * t)) - rg)
        return np.array(h), (np.array(sstar), np.array(along))

    def jacobian(self, model: ArmModel, x: list[float],
                 aux: tuple[Array, Array]) -> list[list[float]]:
        sstar, along = aux
        c = np.array(self.centers)
        k = len(c)
        xa = np.broadcast_to(np.asarray(x, float), (k, model.n))
        pts, Jp = model.arc_points(xa, sstar)                          # (K, N), (K, N, N)
        u = pts - c[:, None]
        u = np.conj(u / np.maximum(np.abs(u), 1e-12))
        Gb = (u[:, :, None] * Jp).real                                  # (K, N, N)
        q, _, J, _ = model.point(np.array(xa), along.astype(complex), hessian=False)
        ug = q - c
        ug = np.conj(ug / np.maximum(np.abs(ug), 1e-12))
        Gg = (ug[:, None] * J).real                                     # (K, N)
        return np.concatenate([Gb, Gg[:, None, :]], axis=1).reshape(-1, model.n).tolist()


@dataclasses.dataclass(frozen=True)
class ObstacleSetup:
    """What one plan needs to keep clear of obstacles (built by ``obstacle_planning``).

    Attributes:
        obstacles: Every obstacle (for the certificates and the plan's record).
        clearance: Set clearance the arm and gripper keep between waypoints (m).
        gripper: The gripper's shape.
        rows: Solver rows for the obstacles within reach, padded by the planner's waypoint
            margin so straight lines between waypoints can keep ``clearance``; None if no
            obstacle is within reach.
        near: Indices of the obstacles within reach (only these are certified; the others
            cannot be reached by any point of the arm).
    """

    obstacles: tuple[Obstacle, ...]
    clearance: float
    gripper: GripperShape
    rows: ObstacleConstraints | None
    near: tuple[int, ...]

    @classmethod
    def build(cls, model: ArmModel, obstacles: Sequence[Obstacle], gripper: GripperShape,
              clearance: float, pad: float) -> "ObstacleSetup":
        reach = float(model.lengths.sum()) + gripper.length + max(model.half_width,
                                                                  gripper.half_width)
        near = tuple(i for i, o in enumerate(obstacles)
                     if abs(o.center - model.base) - o.r - clearance <= reach)
        rows = ObstacleConstraints.build(model, [obstacles[i] for i in near], gripper,
                                         clearance + pad)
        return cls(tuple(obstacles), float(clearance), gripper, rows, near)

    def gaps(self, model: ArmModel, kappas: npt.ArrayLike) -> Array:
        """(..., K) exact gaps to every obstacle."""
        return obstacle_clearance(model, kappas, self.obstacles, self.gripper)

    def certificate(self, model: ArmModel, starts: npt.ArrayLike, ends: npt.ArrayLike,
                    samples: int = 8) -> ObstacleCertificate:
        """Per-obstacle lower bounds along lines (obstacles out of reach: +inf)."""
        a = np.atleast_2d(np.asarray(starts, float))
        lb = np.full((a.shape[0], len(self.obstacles)), np.inf)
        worst = np.zeros_like(lb)
        if self.near:
            cert = certify_obstacle_lines(model, a, ends, [self.obstacles[i] for i in self.near],
                                          self.gripper, self.clearance, samples)
            lb[:, self.near], worst[:, self.near] = cert.lower_bound, cert.worst_tau
        return ObstacleCertificate(lb, worst)

    def certify(self, model: ArmModel, starts: npt.ArrayLike, ends: npt.ArrayLike,
                samples: int = 8) -> Array:
        """(n,) lower bound to the nearest obstacle along each line."""
        return self.certificate(model, starts, ends, samples).line_bound()

    def clear_seeds(self, model: ArmModel, seeds: Array, pad: float) -> Array:
        """The configurations among ``seeds`` (k, N) at least clearance + pad from every
        obstacle, in their order."""
        if not len(seeds):
            return seeds
        return seeds[self.gaps(model, seeds).min(axis=1) >= self.clearance + pad]

    def nearly_solved(self, model: ArmModel, res, rows) -> bool:
        """Whether a solve that ran out of iterations is within :data:`NEAR_TOL` of the palm
        equalities and of every inequality row ``rows`` (grasp_solver's protocol)."""
        if not res.violation <= NEAR_TOL:
            return False
        return rows is None or float(rows.evaluate(model, res.kappa.tolist())[0].min()) >= \
            -NEAR_TOL
