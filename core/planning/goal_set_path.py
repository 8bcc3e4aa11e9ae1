"""A certified path from one arm shape to any of several: the long way round to whichever
final approach is reachable, instead of one fixed goal at a time.

RRT-connect (:mod:`core.planning.clear_path`'s trees, steps and certificates) with the goal tree
rooted at every goal at once: a sample is joined to the nearest node of either tree, and a
connection reaches the goal whose root that node grew from. Half of the samples are drawn near
a node of the growing tree (narrow passages round an obstacle), some near the obstacles'
boundary (a bridge test: a clear sample near one that is not). Every edge is certified
(:meth:`ClearPathProblem.certify`), a seeded generator and an iteration cap make it
deterministic, ``deadline`` (time.thread_time) bounds it.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import numpy.typing as npt

from core.planning.clear_path import ClearPathProblem, _shortcut, _Tree, extend_connect

Array = npt.NDArray[np.float64]

LOCAL_SHARE = 0.5       # of the samples drawn near a node of the growing tree ...
LOCAL_SIGMA = 0.08      # ... with this standard deviation (fraction of the curvature range)
BRIDGE_SHARE = 0.15     # of the samples drawn next to a shape that is not clear
TUCK_STEPS = 9       # values each of the first two segments takes while the coil turns


@dataclasses.dataclass(frozen=True)
class GoalSetPath:
    """A certified path: ``kappas`` from the start to ``goals[goal]``; ``tried`` tree nodes."""

    kappas: Array
    goal: int
    tried: int


def goal_set_path(problem: ClearPathProblem, start: Array, goals: Array, deadline: float,
                  seed: int = 0, samples: int = 8, iterations: int = 3000) -> GoalSetPath | None:
    """A path from ``start`` to one of ``goals`` (k, N) with every line certified (margin >=
    0), or None when none is found within ``iterations`` rounds or before ``deadline``. Goals
    and start must themselves be clear (the caller checks)."""
    m = problem.model
    a = np.asarray(start, float)
    goals = np.asarray(goals, float).reshape(-1, m.n)
    if not len(goals):
        return None
    direct = problem.certify(np.repeat(a[None], len(goals), 0), goals, samples)
    if np.any(direct >= 0.0):
        g = int(np.argmax(direct >= 0.0))
        return GoalSetPath(np.array([a, goals[g]]), g, 1)
    rng = np.random.default_rng(seed)
    w = m.lengths * (np.cumsum(m.lengths[::-1])[::-1] + problem.gripper.length)
    cap = 4 * iterations + len(goals) + 4
    tree_a = _Tree(a, w, cap)
    tree_b = _Tree(goals[0], w, cap)
    for g in goals[1:]:
        tree_b.add(g, -1)       # every goal is a root of the goal tree
    span = m.hi - m.lo
    found = _tucks(problem, tree_a, tree_b, len(goals), samples)
    if found is not None:
        return found

    def edge_ok(p: Array, q: Array) -> bool:
        return bool(problem.certify(p, q, samples)[0] >= 0.0)

    for it in range(iterations):
        if time.thread_time() > deadline:
            break
        grow, other = (tree_a, tree_b) if it % 2 == 0 else (tree_b, tree_a)
        u = rng.random()
        if u < LOCAL_SHARE:
            near = grow.nodes[rng.integers(grow.size)]
            q = np.clip(near + rng.normal(0.0, LOCAL_SIGMA, m.n) * span, m.lo, m.hi)
        elif u < LOCAL_SHARE + BRIDGE_SHARE:
            q = _bridge(problem, rng, m, span)
            if q is None:
                continue
        else:
            q = rng.uniform(m.lo, m.hi)
        met = extend_connect(problem, w, grow, other, q, cap, edge_ok)
        if met is not None:
            ia, ib = met if grow is tree_a else met[::-1]
            left, right = tree_a.branch(ia), tree_b.branch(ib)[1:]
            chain = np.array(left[::-1] + right)
            root = _root(tree_b, ib)
            path = _shortcut(problem, chain, samples)
            return GoalSetPath(path, int(root), tree_a.size + tree_b.size)
        if tree_a.size >= cap - 1 or tree_b.size >= cap - 1:
            break
    return None


def _tucks(problem: ClearPathProblem, tree_a: _Tree, tree_b: _Tree, n_goals: int,
           samples: int) -> GoalSetPath | None:
    """Seed the start's tree with the arm curled up (every segment at its curvature limit, to
    either side) and that coil turned about the base (the first segments swept through their
    range): a compact shape turns where a long one cannot. Each added only along a certified
    line from its parent; a path if one of them reaches a goal in a straight line."""
    m = problem.model
    for side, other in ((m.lo, m.hi), (m.hi, m.lo)):
        if not _line_ok(problem, tree_a.nodes[0], side, samples):
            continue
        coil = tree_a.add(side.copy(), 0)
        for seg in range(min(2, m.n)):          # the coil turned about the base
            prev = coil
            for v in np.linspace(side[seg], other[seg], TUCK_STEPS)[1:]:
                q = tree_a.nodes[prev].copy()
                q[seg] = v
                if _line_ok(problem, tree_a.nodes[prev], q, samples):
                    prev = tree_a.add(q, prev)
        prev = coil                             # the coil rolled over, root first
        for seg in range(m.n):
            for v in np.linspace(side[seg], other[seg], 5)[1:]:
                q = tree_a.nodes[prev].copy()
                q[seg] = v
                if not _line_ok(problem, tree_a.nodes[prev], q, samples):
                    break
                prev = tree_a.add(q, prev)
            else:
                continue
            break
    nodes = tree_a.nodes[:tree_a.size]
    goals = tree_b.nodes[:n_goals]
    for i in range(1, len(nodes)):
        ok = problem.certify(np.repeat(nodes[i][None], n_goals, 0), goals, samples) >= 0.0
        if np.any(ok):
            g = int(np.argmax(ok))
            chain = np.array(tree_a.branch(i)[::-1] + [goals[g]])
            return GoalSetPath(_shortcut(problem, chain, samples), g, tree_a.size)
    return None


def _line_ok(problem: ClearPathProblem, p: Array, q: Array, samples: int) -> bool:
    return bool(problem.margin(q) >= 0.0 and problem.certify(p, q, samples)[0] >= 0.0)


def _root(tree: _Tree, i: int) -> int:
    while tree.parent[i] >= 0:
        i = int(tree.parent[i])
    return i


def _bridge(problem: ClearPathProblem, rng, m, span: Array) -> Array | None:
    """A clear shape next to one that is not (near an obstacle's boundary), or None."""
    p = rng.uniform(m.lo, m.hi)
    q = np.clip(p + rng.normal(0.0, LOCAL_SIGMA, m.n) * span, m.lo, m.hi)
    mp, mq = problem.margin(p), problem.margin(q)
    if (mp < 0.0) == (mq < 0.0):
        return None
    return p if mp >= 0.0 else q
