"""Refuse grasps that cannot work, in plain words, before (and instead of) planning them.

Cheap geometric checks run first (bad numbers, object larger than the gripper opens, object on
the base, beyond any reach, overlapping the arm or the gripper as they stand). Whether an object
within that bound can really be reached needs the kinematics: :func:`find_final_config` looks
for any configuration that puts the palm on the final approach circle with the arm clear of the
object, from the current configuration and from a cached table of sampled configurations; the
planner calls it only when its warm-started solves fail, and refuses when it finds none.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import numpy.typing as npt

from core.planning import grasp_solver as gs
from core.planning.arm_model import ArmModel
from core.planning.clearance import gripper_clearance

Array = npt.NDArray[np.float64]


class GraspRefused(ValueError):
    """The grasp cannot be planned; ``str(exc)`` tells the operator why.

    Attributes:
        reason: Short code: ``bad_input``, ``too_large``, ``on_base``, ``out_of_reach``,
            ``on_arm``, ``on_gripper``.
    """

    def __init__(self, reason: str, message: str):
        super().__init__(message)
        self.reason = reason

    def about(self, noun: str) -> GraspRefused:
        """The same refusal worded for what was really asked about (the planner words it for
        "the object"; the bin, placed by planning an object's grasp at its point, says "the
        bin"): ``noun`` replaces "the object" in the message."""
        text = str(self).replace("The object", f"The {noun}").replace("the object", f"the {noun}")
        return GraspRefused(self.reason, text)

    def __reduce__(self):  # pickled as it was built: a refusal crosses the planning process
        return (type(self), (self.reason, str(self)))


def _mm(v: float) -> str:
    """A distance (m) as the screen shows it: mm, one decimal."""
    return f"{1e3 * v:.1f} mm"


def _beyond(dist: float, reach: float) -> str:
    """How far ``dist`` lies past ``reach`` (m), worded so that it never reads as equal: below
    0.1 mm it says "less than 0.1 mm" rather than printing two equal figures."""
    excess = dist - reach
    return "less than 0.1 mm" if excess < 0.5e-4 else _mm(excess)


CONTACT_TOLERANCE_M = 0.001
"""How far an object may seem to overlap the arm or the gripper's fingers as they stand and
still be planned for (m): an object the arm touches (pushed by it during an approach, when the
state machine re-plans from there) is measured up to a few marker-noise sigmas (0.3 mm each)
inside it. Deeper overlap is refused: the object is really on the arm."""


def check_request(robot, model: ArmModel, kappa_meas: Array, center: complex, radius: float,
                  base_keepout: float) -> None:
    """Geometric checks that need no optimisation; raise :class:`GraspRefused` on failure.

    An object touching the arm or the gripper passes: the overlap checks allow
    :data:`CONTACT_TOLERANCE_M`, and the gripper as it stands is its fingers (the robot file's
    ``[sim.gripper] finger_half_width``, 8 mm on the soft arm), not the wider drawn and planned
    gripper (``[gripper] half_width``, 12 mm): an object the fingers pushed lies against them,
    which the drawn gripper would count as a 4 mm overlap."""
    if not (math.isfinite(center.real) and math.isfinite(center.imag) and math.isfinite(radius)):
        raise GraspRefused("bad_input", "The object position and radius must be finite numbers.")
    if radius <= 0.0:
        raise GraspRefused("bad_input", f"The object radius must be positive, got {radius:g} m.")
    g = robot.gripper
    if radius > g.max_object_radius:
        raise GraspRefused(
            "too_large",
            f"The object is too large for the gripper: its diameter is {_mm(2 * radius)}, the "
            f"gripper closes around objects up to {_mm(2 * g.max_object_radius)} across.")
    dist = abs(center - model.base)
    if dist < radius + base_keepout:
        raise GraspRefused(
            "on_base",
            f"The object is on the arm's base ({_mm(dist)} from it); place it at least "
            f"{_mm(radius + base_keepout)} away.")
    final_offset = abs(complex(g.w_off_along, 2.0 * g.g_off + radius))
    reach = float(model.lengths.sum()) + final_offset
    if dist > reach:
        raise GraspRefused(
            "out_of_reach",
            f"The object is out of reach: it is {_mm(dist)} from the arm's base, "
            f"{_beyond(dist, reach)} beyond the {_mm(reach)} at which the gripper can still "
            f"reach around an object of this size.")
    arm_gap = model.clearance_py(kappa_meas.tolist(), center, radius)
    if arm_gap < -CONTACT_TOLERANCE_M:
        raise GraspRefused(
            "on_arm",
            f"The object overlaps the arm where it stands now (by {_mm(-arm_gap)}); move the "
            f"object or the arm first.")
    fingers = min(g.half_width, robot.sim.gripper.finger_half_width)
    grip_gap = gripper_clearance(model, kappa_meas, center, radius, g.length, fingers)
    if grip_gap < -CONTACT_TOLERANCE_M:
        raise GraspRefused(
            "on_gripper",
            f"The object overlaps the gripper where it stands now (by {_mm(-grip_gap)}); move "
            f"the object or the arm first.")


@functools.lru_cache(maxsize=8)
def _seed_table(key: tuple) -> tuple[Array, Array, Array]:
    """Sampled configurations, their tip points and tip directions exp(i theta) (memoised)."""
    lengths, base, theta0, lo, hi, hw, count = key
    model = ArmModel(np.array(lengths), base, theta0, np.array(lo), np.array(hi), hw)
    rng = np.random.default_rng(7)
    n = len(lengths)
    # Uniform samples plus constant-curvature arcs (the shapes the optimum tends to take).
    uni = rng.uniform(np.array(lo), np.array(hi), size=(count, n))
    arcs = np.linspace(lo[0], hi[0], 33)[:, None] * np.ones(n)
    kappas = np.concatenate([arcs, uni])
    pts, th = model.frames(kappas)
    return kappas, pts[:, -1], np.exp(1j * th[:, -1])


@functools.lru_cache(maxsize=8)
def _table_key(model: ArmModel, size: int) -> tuple:
    """The seed table's cache key of a model (memoised per model object)."""
    return (tuple(model.lengths.tolist()), model.base, model.theta0, tuple(model.lo.tolist()),
            tuple(model.hi.tolist()), model.half_width, int(size))


def _table(model: ArmModel, size: int) -> tuple[Array, Array, Array]:
    return _seed_table(_table_key(model, size))


@functools.lru_cache(maxsize=16)
def _cost_terms(key: tuple, kappa_off: tuple, weights: tuple) -> tuple[Array, float, float]:
    """Per table configuration sum w k^2 - 2 k . (w ko), and sum w ko^2 and mean(w): the parts
    of :func:`best_start`'s score that depend only on kappa_off and the weights (memoised, as
    a plan's start configuration and weights rarely change between plans)."""
    kappas = _seed_table(key)[0]
    w = np.array(weights)
    ko = np.array(kappa_off)
    score = (kappas * kappas) @ w - 2.0 * (kappas @ (w * ko))
    score.flags.writeable = False
    return score, float(w @ (ko * ko)), float(w.mean())


def seeds_near(model: ArmModel, center: complex, offset: complex, count: int,
               table_size: int) -> Array:
    """Table configurations whose object-centre point lies nearest ``center`` (count, N)."""
    kappas, tips, heading = _table(model, table_size)
    resid = np.abs(tips + offset * heading - center)
    idx = np.argpartition(resid, count)[:count]
    return kappas[idx[np.argsort(resid[idx])]]


def best_start(model: ArmModel, center: complex, offset: complex, kappa_off: Array,
               weights: Array, table_size: int, beta: float = 1e5) -> Array:
    """Start for the first waypoint: the table configuration (or kappa_off itself) that best
    trades the cost sum R (kappa - kappa_off)^2 against beta * (distance of its object-centre
    point from ``center``)^2. Far cheaper than letting the SQP walk out of a straight arm."""
    key = _table_key(model, table_size)
    kappas, tips, heading = _seed_table(key)
    ko = np.asarray(kappa_off, float).tolist()
    # sum_n w_n (k_n - ko_n)^2 = sum w k^2 - 2 k . (w ko) + const, dropping the constant.
    w = tuple(np.asarray(weights, float).tolist())
    base, ko_cost, w_mean = _cost_terms(key, tuple(ko), w)
    r = tips + offset * heading - center
    score = base + (beta * w_mean) * (r.real * r.real + r.imag * r.imag)
    k = int(np.argmin(score))
    q0, _ = model.point_py(ko, offset)
    if beta * w_mean * abs(q0 - center) ** 2 <= score[k] + ko_cost:
        return np.asarray(kappa_off, float)
    return kappas[k]


def find_final_config(model: ArmModel, center: complex, radius: float, offset: complex,
                      kappa_meas: Array, weights: Array, margin: float, table_size: int,
                      tries: int, extra=None,
                      seeds: list[Array] | None = None) -> tuple[Array | None, int]:
    """Any configuration with the palm on the final circle and the arm body clear of the object
    (and of ``extra``'s constraints, e.g. obstacles, when given; ``seeds`` then replace the
    table configurations tried after kappa_meas and the straight arm).

    Returns:
        ``(kappa or None, solves)``: the first witness found and the number of solves run.
    """
    starts = [np.asarray(kappa_meas, float), np.zeros(model.n)]
    if seeds is None:
        starts += list(seeds_near(model, center, offset, tries, table_size))
    else:
        starts += list(seeds)
    rho = radius + model.half_width + margin
    solves = 0
    for x0 in starts[:tries + 2 if seeds is None else len(starts)]:
        res = gs.solve(model, center, offset, x0, kappa_meas, weights, clearance=extra)
        solves += 1
        if res.ok and model.clearance_py(res.kappa.tolist(), center, radius) < margin:
            res = gs.solve(model, center, offset, res.kappa, kappa_meas, weights, res.lam,
                           gs.joined(gs.Clearance(center, rho), extra))
            solves += 1
        if res.ok:
            return res.kappa, solves
    return None, solves
