"""Certified motions between two arm shapes around obstacles: the carry to the bin and the
long way round to an approach, when the straight line in kappa would sweep through one.

The curvature controller moves the arm along straight lines in kappa between targets (ruckig,
phase-synchronised, rest to rest). :func:`clear_path` returns the targets -- the goal alone
when the straight line keeps the set clearance, else a few via configurations -- such that
every line between them is *certified* (:func:`core.planning.clearance.certify_function`, a
guaranteed lower bound, not a sampled estimate) to keep:

* the arm body and the straight gripper ``clearance`` + ``pad`` from every obstacle disk
  (:func:`core.planning.obstacles.obstacle_clearance`);
* a held object (a disk of the grasped radius at the gripper's finger, :class:`HeldObject`)
  as far from every obstacle, or, when it starts closer (an object grasped next to an
  obstacle), never closer than it starts less :data:`HELD_SLACK`;
* extra disks with their own required gap for the arm body alone (``extra``: the object to
  grasp, which the arm must not push on its way round while the gripper reaches around it).

The search is RRT-connect in the box of curvature limits (every edge certified; a seeded
``numpy`` generator and an iteration cap make it deterministic), then a greedy shortcut (the
farthest certified target from each kept one). Bounded by ``budget_s``; when no path is found
:class:`ClearPathRefused` names the obstacle the straight motion comes closest to.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence

import numpy as np
import numpy.typing as npt

from core.planning.arm_model import ArmModel
from core.planning.clearance import certify_function
from core.planning.feasibility import GraspRefused
from core.planning.obstacles import GripperShape, Obstacle, line_rate, obstacle_clearance

Array = npt.NDArray[np.float64]

HELD_SLACK = 0.003      # m: a held object that starts inside the clearance may lose this much
START_SLACK = 0.0005    # m: an arm that starts inside clearance + pad keeps its gap less this
LIMIT_SLACK = 2.0       # 1/m: a measured start this far past a curvature limit (sensor noise,
                        # overshoot at the limit: ~1 1/m seen in the simulator) is the limit
STEP_M = 0.06           # m: longest RRT extension (bound on any arm point's displacement)
MAX_ITERATIONS = 600    # RRT-connect rounds (the deterministic cap; budget_s cuts earlier)
LOCAL_SHARE = 0.5       # of the samples drawn near a node of the growing tree ...
LOCAL_SIGMA = 0.08      # ... with this standard deviation (fraction of the curvature range)


class ClearPathRefused(GraspRefused):
    """No certified path was found (or the start or goal itself is too close).

    Attributes:
        obstacle: Name of the obstacle in the way.
    """

    def __init__(self, message: str, obstacle: str):
        super().__init__("obstacle", message)
        self.obstacle = obstacle

    def __reduce__(self):
        return (type(self), (str(self), self.obstacle))


@dataclasses.dataclass(frozen=True)
class HeldObject:
    """A disk held at the gripper: its centre's offset in the tip frame and its radius (m)."""

    offset: complex
    radius: float

    @classmethod
    def at_finger(cls, robot, radius: float, side: str = "left") -> "HeldObject":
        """The object the ``side`` finger holds (where the grasp planner puts it)."""
        g = robot.gripper
        normal = 2.0 * g.g_off + float(radius)
        return cls(complex(g.w_off_along, -normal if side == "right" else normal),
                   float(radius))


@dataclasses.dataclass(frozen=True)
class ClearPath:
    """A certified path: ``kappas`` (m, N) from the start (row 0) to the goal (last row).

    Attributes:
        kappas: The start, the via configurations, the goal.
        bound: (m-1,) certified lower bound of the smallest margin along each line (m; the
            margin is the gap less the required one, so >= 0 everywhere).
        straight: True when the straight line was clear (no vias).
        tried: Configurations the search added to its trees.
        ms: Planning time.
    """

    kappas: Array
    bound: Array
    straight: bool
    tried: int
    ms: float

    @property
    def vias(self) -> Array:
        """The targets after the start: via configurations then the goal."""
        return self.kappas[1:]


def _mm(v: float) -> str:
    return f"{v * 1e3:.0f} mm"


class ClearPathProblem:
    """Margins (gap less the required gap) of an arm shape to every disk, and line certificates.

    Args:
        model: The arm.
        gripper: The gripper's shape.
        obstacles: Disks the arm, gripper and held object keep ``clearance`` from.
        clearance: Required gap (m), ``pad`` added for the planner's own margin.
        held: Held object, if any; its required gap is capped by its gap at ``start``.
        start: The start configuration (for the held object's cap).
        extra: More disks as (obstacle, required gap) for the arm body only.
    """

    def __init__(self, model: ArmModel, gripper: GripperShape, obstacles: Sequence[Obstacle],
                 clearance: float, pad: float = 0.0, held: HeldObject | None = None,
                 start: Array | None = None,
                 extra: Sequence[tuple[Obstacle, float]] = ()):
        self.model, self.gripper, self.held = model, gripper, held
        self.disks = tuple(obstacles) + tuple(o for o, _ in extra)
        self.need = np.array([clearance + pad] * len(obstacles) + [g for _, g in extra], float)
        self.clearance = float(clearance)
        self.n_obstacles = len(obstacles)
        reach = abs(held.offset) if held is not None else 0.0
        self._rate_grip = GripperShape(max(gripper.length, reach), 0.0)
        self.pad = float(pad)
        if start is not None and len(obstacles):
            # A start closer than clearance + pad (a grasp pose planned with a smaller margin)
            # keeps what it has, never less than the clearance.
            now = obstacle_clearance(model, np.asarray(start, float), obstacles, gripper)
            self.need[:len(obstacles)] = np.maximum(
                clearance, np.minimum(clearance + pad, now - START_SLACK))
        self.held_need = np.zeros(len(obstacles))
        if held is not None and len(obstacles):
            need = np.full(len(obstacles), clearance + pad)
            if start is not None:
                now = self.held_gaps(np.asarray(start, float))
                need = np.minimum(need, np.maximum(now - HELD_SLACK, 0.0))
            self.held_need = need

    def held_gaps(self, kappas: Array) -> Array:
        """(..., K) gaps of the held object to the obstacles (not the extra disks)."""
        pts, th = self.model.frames(kappas)
        c = pts[..., -1] + np.exp(1j * th[..., -1]) * self.held.offset
        obs = self.disks[:self.n_obstacles]
        centers = np.array([o.center for o in obs])
        radii = np.array([o.r for o in obs])
        return np.abs(c[..., None] - centers) - radii - self.held.radius

    def margins(self, kappas: npt.ArrayLike) -> Array:
        """(..., D) margin to each disk (obstacles first, then the extra ones); >= 0 is clear."""
        k = np.asarray(kappas, float)
        out = self._gaps(k) - self.need
        if self.held is not None and self.n_obstacles:
            held = self.held_gaps(k) - self.held_need
            out[..., :self.n_obstacles] = np.minimum(out[..., :self.n_obstacles], held)
        return out

    def _gaps(self, k: Array) -> Array:
        """(..., D) gaps of the arm and gripper to the obstacles, of the body to the extras."""
        n = self.n_obstacles
        out = np.empty(k.shape[:-1] + (len(self.disks),))
        out[..., :n] = obstacle_clearance(self.model, k, self.disks[:n], self.gripper)
        for j, o in enumerate(self.disks[n:], start=n):
            out[..., j] = self.model.body_clearance(k, o.center, o.r)
        return out

    def gaps(self, kappas: Array) -> Array:
        """(..., D) gaps to each disk, the held object's folded into the obstacles' (m)."""
        gaps = self._gaps(kappas)
        if self.held is not None and self.n_obstacles:
            gaps[..., :self.n_obstacles] = np.minimum(gaps[..., :self.n_obstacles],
                                                      self.held_gaps(kappas))
        return gaps

    def margin(self, kappas: npt.ArrayLike) -> Array:
        """(...,) smallest margin over every disk (inf without disks)."""
        m = self.margins(kappas)
        return m.min(axis=-1, initial=math.inf)

    def certify(self, starts: Array, ends: Array, samples: int = 8) -> Array:
        """(n,) certified lower bounds of the margin along the lines starts -> ends."""
        a, b = np.atleast_2d(starts), np.atleast_2d(ends)
        if not self.disks:
            return np.full(a.shape[0], math.inf)
        lam = line_rate(self.model, b - a, self._rate_grip)
        return certify_function(self.margin, lam, a, b, 0.0, samples).lower_bound

    def worst(self, a: Array, b: Array) -> tuple[int, float]:
        """The disk the straight line a -> b comes closest to and that smallest gap (dense)."""
        tau = np.linspace(0.0, 1.0, 129)[:, None]
        gaps = self.gaps(a + tau * (b - a))
        per = (gaps - self.need).min(axis=0)
        j = int(np.argmin(per))
        return j, float(gaps[:, j].min())


def _what(problem: ClearPathProblem) -> str:
    return "arm, gripper and held object" if problem.held is not None else "arm and gripper"


def too_close(problem: ClearPathProblem, k: Array, name: str) -> tuple[str, str] | None:
    """Why the arm at shape ``k`` (``name``: "the bin pose", "a relay", ...) is closer than
    ``problem``'s clearance to a disk, and that disk's name; None when it is not. The one
    wording of this refusal (the planner's start and goal, the bin's check before a task)."""
    m = problem.margins(k)
    if not len(m) or m.min() >= 0.0:
        return None
    j = int(np.argmin(m))
    o = problem.disks[j]
    gap = float(problem.gaps(k)[j])
    where = f"overlap it by {_mm(-gap)}" if gap < 0 else f"come {_mm(gap)} from it"
    pad = f" (planned with {_mm(problem.pad)} more)" if problem.pad > 0 else ""
    return (f"{name[:1].upper() + name[1:]} is too close to {o.name}: the {_what(problem)} "
            f"{where}, the clearance is {_mm(problem.clearance)}{pad}. Move {o.name} or "
            f"{'the bin' if 'bin' in name else 'the object'}, or lower the clearance.", o.name)


def _refuse_end(problem: ClearPathProblem, k: Array, name: str) -> None:
    why = too_close(problem, k, name)
    if why is not None:
        raise ClearPathRefused(*why)


def within_limits(model: ArmModel, start: Array) -> Array:
    """A measured start (1/m, N) with the curvatures up to :data:`LIMIT_SLACK` past a limit set
    to that limit; ValueError naming the segment when one is further out."""
    past = np.maximum(model.lo - start, start - model.hi)
    i = int(np.argmax(past))
    if past[i] > LIMIT_SLACK:
        raise ValueError(f"the start is outside the curvature limits (segment {i + 1}: "
                         f"{start[i]:.2f} 1/m, limits {model.lo[i]:.2f} to {model.hi[i]:.2f})")
    return np.clip(start, model.lo, model.hi)


def clear_path(problem: ClearPathProblem, start: npt.ArrayLike, goal: npt.ArrayLike, *,
               budget_s: float = 1.0, seed: int = 0, samples: int = 8,
               goal_name: str = "the goal pose", hints: Sequence[Array] = ()) -> ClearPath:
    """A certified path from ``start`` to ``goal`` (see the module docstring).

    ``hints`` is a chain of configurations from ``start`` worth trying first (e.g. the
    approach that brought the arm there, backwards): its certified prefix seeds the start's
    tree, and each of its configurations is tried straight to the goal.

    Raises:
        ClearPathRefused: the start or goal is closer than required to a disk, or no path was
            found within ``budget_s`` / :data:`MAX_ITERATIONS` (naming the obstacle).
        ValueError: start or goal of the wrong shape, not finite or outside the limits.
    """
    t0 = time.perf_counter()
    c0 = time.thread_time()     # the budget is this thread's CPU time: load does not change it
    m = problem.model
    a = np.asarray(start, float)
    b = np.asarray(goal, float)
    for name, k in (("start", a), ("goal", b)):
        if k.shape != (m.n,) or not np.isfinite(k).all():
            raise ValueError(f"the {name} must be {m.n} finite curvatures")
    a = within_limits(m, a)
    if np.any(b < m.lo - 1e-9) or np.any(b > m.hi + 1e-9):
        raise ValueError("the goal is outside the curvature limits")
    _refuse_end(problem, a, "the arm's shape at the start")
    _refuse_end(problem, b, goal_name)
    lb = problem.certify(a, b, samples)
    if lb[0] >= 0.0:
        return ClearPath(np.array([a, b]), lb, True, 0, (time.perf_counter() - t0) * 1e3)
    deadline = c0 + budget_s
    path, tried = _rrt_connect(problem, a, b, deadline, seed, samples, hints)
    if path is None:
        j, gap = problem.worst(a, b)
        o = problem.disks[j]
        how = (f"passes through it by {_mm(-gap)}" if gap < 0 else
               f"passes {_mm(gap)} from it")
        raise ClearPathRefused(
            f"No motion found from the arm's shape to {goal_name} that keeps the "
            f"{_what(problem)} {_mm(problem.clearance)} clear of {o.name} ({tried} shapes "
            f"tried in {time.perf_counter() - t0:.1f} s); the direct motion {how}. Move "
            f"{o.name}, or lower the clearance.", o.name)
    path = _shortcut(problem, path, samples)
    bound = problem.certify(path[:-1], path[1:], samples)
    assert np.all(bound >= 0.0)
    return ClearPath(path, bound, False, tried, (time.perf_counter() - t0) * 1e3)


class _Tree:
    def __init__(self, root: Array, weights: Array, cap: int):
        self.nodes = np.empty((cap, root.shape[0]))
        self.nodes[0] = root
        self.parent = np.full(cap, -1, np.intp)
        self.size = 1
        self.w = weights

    def nearest(self, q: Array) -> int:
        d = np.abs(self.nodes[:self.size] - q) @ self.w
        return int(np.argmin(d))

    def add(self, q: Array, parent: int) -> int:
        i = self.size
        self.nodes[i], self.parent[i] = q, parent
        self.size += 1
        return i

    def branch(self, i: int) -> list[Array]:
        out = []
        while i >= 0:
            out.append(self.nodes[i])
            i = int(self.parent[i])
        return out


def _steer(w: Array, q_from: Array, q_to: Array) -> tuple[Array, bool]:
    d = float(np.abs(q_to - q_from) @ w)
    if d <= STEP_M:
        return q_to.copy(), True
    return q_from + (q_to - q_from) * (STEP_M / d), False


def extend_connect(problem: ClearPathProblem, w: Array, grow: _Tree, other: _Tree, q: Array,
                   cap: int, edge_ok: Callable[[Array, Array], bool]) -> tuple[int, int] | None:
    """One RRT-connect step: extend ``grow`` one steer toward ``q`` (a clear node along a clear
    line), then grow ``other`` toward that new node while every step is clear. Returns the
    node indices (in ``grow``, in ``other``) where the trees met, else None."""
    i = grow.nearest(q)
    qn, _ = _steer(w, grow.nodes[i], q)
    if problem.margin(qn) < 0.0 or not edge_ok(grow.nodes[i], qn):
        return None
    new = grow.add(qn, i)
    j = other.nearest(qn)
    while other.size < cap - 1:
        qs, reached = _steer(w, other.nodes[j], qn)
        if not edge_ok(other.nodes[j], qs):
            return None
        j = other.add(qs, j)
        if reached:
            return new, j
    return None


def _rrt_connect(problem: ClearPathProblem, a: Array, b: Array, deadline: float, seed: int,
                 samples: int, hints: Sequence[Array] = ()) -> tuple[Array | None, int]:
    m = problem.model
    rng = np.random.default_rng(seed)
    w = m.lengths * (np.cumsum(m.lengths[::-1])[::-1] + problem.gripper.length)
    cap = 4 * MAX_ITERATIONS + 4
    trees = [_Tree(a, w, cap), _Tree(b, w, cap)]

    def edge_ok(p: Array, q: Array) -> bool:
        return bool(problem.certify(p, q, samples)[0] >= 0.0)

    seeded = _seed_hints(problem, trees[0], np.asarray(hints, float).reshape(-1, m.n), b,
                         samples)
    if seeded is not None:
        return seeded, trees[0].size

    for it in range(MAX_ITERATIONS):
        if time.thread_time() > deadline:
            break
        grow, other = trees[it % 2], trees[1 - it % 2]
        if rng.random() < LOCAL_SHARE:  # near a node of the tree: narrow passages
            near = grow.nodes[rng.integers(grow.size)]
            q = np.clip(near + rng.normal(0.0, LOCAL_SIGMA, m.n) * (m.hi - m.lo), m.lo, m.hi)
        else:
            q = rng.uniform(m.lo, m.hi)
        met = extend_connect(problem, w, grow, other, q, cap, edge_ok)
        if met is not None:
            left, right = grow.branch(met[0]), other.branch(met[1])[1:]
            chain = left[::-1] + right
            if it % 2 == 1:
                chain = chain[::-1]
            return np.array(chain), trees[0].size + trees[1].size
        if grow.size >= cap - 1 or other.size >= cap - 1:
            break
    return None, trees[0].size + trees[1].size


def _seed_hints(problem: ClearPathProblem, tree: _Tree, hints: Array, b: Array,
                samples: int) -> Array | None:
    """Add the certified prefix of ``hints`` to the start's tree; a path if one of them
    reaches the goal ``b`` in a straight line."""
    i = 0
    for q in hints[:max(0, tree.nodes.shape[0] - 2)]:
        if problem.margin(q) < 0.0 or problem.certify(tree.nodes[i], q, samples)[0] < 0.0:
            break
        i = tree.add(q, i)
    if tree.size == 1:
        return None
    nodes = tree.nodes[1:tree.size]
    ok = problem.certify(nodes, np.repeat(b[None], len(nodes), 0), samples) >= 0.0
    if not np.any(ok):
        return None
    j = 1 + int(np.argmax(ok))
    return np.array(tree.branch(j)[::-1] + [b])


def _shortcut(problem: ClearPathProblem, path: Array, samples: int) -> Array:
    """From each kept configuration, jump to the farthest one a certified line reaches."""
    keep = [0]
    i = 0
    n = len(path)
    while i < n - 1:
        later = np.arange(n - 1, i, -1)
        ok = problem.certify(np.repeat(path[i][None], len(later), 0), path[later], samples)
        j = int(later[np.argmax(ok >= 0.0)]) if np.any(ok >= 0.0) else i + 1
        keep.append(j)
        i = j
    return path[keep]
