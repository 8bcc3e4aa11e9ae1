"""Where on the table a grasp can be planned: a grid map for the console's shading.

Every cell centre of a table grid is planned with Algorithm 1 from a given start (the paper's
straight arm by default) for one object radius, on the side of the arm the cell lies on when the
gripper closes to both sides (:class:`core.planning.sides.SidedPlanner`; the paper's single
finger plans every cell for the left). To keep the map cheap,
cells that no sampled final configuration comes near (the object centre a configuration holds at
the final radius, arm body clear) are marked unreachable without planning; the others are
planned, with ``levels`` (the console's ``DEFAULT_LEVELS`` = 2) coarse to fine: every 4th cell
first, then a finer cell only where the coarser cells around it disagree (elsewhere it takes
their common status), so mainly the boundaries between outcomes are planned at full
resolution. Pure and single-threaded; ``python -m core.planning.reachability``
(:mod:`core.planning.reachability.__main__`) prints a map as JSON (the console runs that in a low-priority child process, once per robot file, and caches
it on disk: :mod:`console.core.reach_job`).
"""

from __future__ import annotations

import dataclasses
import json
import math
from typing import Callable

import numpy as np
import numpy.typing as npt

from core.planning.arm_model import ArmModel
from core.planning.feasibility import GraspRefused
from core.planning.plan_types import PlannerConfig
from core.planning.sides import SidedPlanner

Array = npt.NDArray[np.float64]

UNREACHABLE, PLANNABLE, FAILS = 0, 1, 2
# Bump when a change to this module or to the planner can change a map: cached maps
# (console.reach_cache) of another version are recomputed. 3: both sides (core.planning.sides).
ALGORITHM_VERSION = 3
DEFAULT_LEVELS = 2          # coarse-to-fine levels of the console's map (about half the plans)


@dataclasses.dataclass(frozen=True)
class ReachMap:
    """Grid of planning outcomes.

    Attributes:
        xs, ys: Cell-centre coordinates (nx,), (ny,) in m.
        status: (ny, nx) int8: UNREACHABLE (refused), PLANNABLE (plan succeeded) or FAILS
            (a final pose exists but Algorithm 1 could not plan the approach).
        radius: Object radius the map was computed for.
    """

    xs: Array
    ys: Array
    status: npt.NDArray[np.int8]
    radius: float

    @property
    def step(self) -> float:
        """Cell width along x (m)."""
        return float(self.xs[1] - self.xs[0]) if len(self.xs) > 1 else 0.0

    @property
    def step_y(self) -> float:
        """Cell height along y (m)."""
        return float(self.ys[1] - self.ys[0]) if len(self.ys) > 1 else 0.0

    def lookup(self, x: float, y: float) -> int:
        """Status of the cell containing (x, y); UNREACHABLE outside the grid."""
        i = int(round((y - self.ys[0]) / self.step_y)) if self.step_y else 0
        j = int(round((x - self.xs[0]) / self.step)) if self.step else 0
        if 0 <= i < len(self.ys) and 0 <= j < len(self.xs):
            return int(self.status[i, j])
        return UNREACHABLE


def map_planner(robot) -> SidedPlanner:
    """The planner whose answers the map records, one cell at a time (on the cell's side)."""
    # Coarser search than an operator's plan (fewer restarts and inserted waypoints): the map
    # is a guide, the plan for a placed object is authoritative.
    cfg = dataclasses.replace(PlannerConfig.from_robot(robot), max_restarts=2, max_insertions=1)
    return SidedPlanner(robot, cfg)


def cell_status(planner: SidedPlanner, kappa_meas: npt.ArrayLike, x: float, y: float,
                radius: float) -> int:
    """The planner's own answer for one cell: PLANNABLE, FAILS or UNREACHABLE (refused)."""
    try:
        plan = planner.plan(kappa_meas, (x, y), radius)
    except GraspRefused:
        return UNREACHABLE
    return PLANNABLE if plan.success else FAILS


def grid_axis(lo: float, hi: float, step: float) -> Array:
    """Cell centres from ``lo`` to ``hi`` inclusive, evenly spaced, at most ``step`` apart."""
    n = max(int(math.ceil((hi - lo) / step - 1e-9)), 1) + 1
    return np.linspace(lo, hi, n)


def _lattice(n: int, stride: int) -> npt.NDArray[np.int64]:
    """Indices 0, stride, 2 stride, ... of an axis of ``n`` cells, always with the last one."""
    idx = np.arange(0, n, stride)
    return idx if idx[-1] == n - 1 else np.append(idx, n - 1)


def reachability_map(robot, radius: float, x_range: tuple[float, float],
                     y_range: tuple[float, float], step: float,
                     kappa_meas: npt.ArrayLike | None = None, samples: int = 40000,
                     near: float = 0.02, levels: int = 0,
                     should_stop: Callable[[], bool] | None = None,
                     progress: Callable[[float], None] | None = None) -> ReachMap:
    """Plan an object of ``radius`` at every grid cell (see the module docstring).

    Args:
        robot: A :class:`core.robots.SoftArm`.
        radius: Object radius (m).
        x_range, y_range: Grid extent (m): cell centres from the lower to the upper value
            inclusive, evenly spaced and at most ``step`` apart.
        step: Largest cell size (m).
        kappa_meas: Start configuration (default straight).
        samples: Random configurations used to skip cells that are certainly far from reach.
        near: Cells farther than this from every sampled final object position are skipped.
        levels: Coarse to fine: the cells ``2**levels`` apart are planned first; a cell of the
            next finer lattice is planned only where the (up to 2 x 2) coarser cells around it
            differ, otherwise it takes their common status (0, the default, plans every
            candidate cell; the console uses ``DEFAULT_LEVELS``).
        should_stop: Polled once per planned cell; when it returns True the map is returned
            as far as it got (the remaining cells stay UNREACHABLE).
        progress: Called with the fraction (0..1) of candidate cells decided so far.
    """
    if step <= 0 or radius <= 0 or levels < 0:
        raise ValueError("step and radius must be positive, levels not negative")
    planner = map_planner(robot)
    km = np.zeros(planner.model.n) if kappa_meas is None else np.asarray(kappa_meas, float)
    xs, ys = grid_axis(*x_range, step), grid_axis(*y_range, step)
    candidate = _candidates(robot, planner.model, radius, xs, ys, samples, near)
    status = np.zeros(candidate.shape, np.int8)
    known = ~candidate
    total = max(int(candidate.sum()), 1)

    stride = 2 ** levels
    prev: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]] | None = None
    while stride >= 1:
        lx, ly = _lattice(len(xs), stride), _lattice(len(ys), stride)
        for i in ly:
            for j in lx:
                if known[i, j]:
                    continue
                if prev is not None:
                    px, py = prev
                    a = int(np.searchsorted(px, j, "right")) - 1
                    b = int(np.searchsorted(py, i, "right")) - 1
                    block = status[np.ix_(py[b:b + 2], px[a:a + 2])]
                    if (block == block.flat[0]).all():
                        status[i, j] = block.flat[0]
                        known[i, j] = True
                        continue
                if should_stop is not None and should_stop():
                    return ReachMap(xs, ys, status, float(radius))
                status[i, j] = cell_status(planner, km, xs[j], ys[i], radius)
                known[i, j] = True
                if progress is not None:
                    progress(1.0 - float((~known).sum()) / total)
        prev = (lx, ly)
        stride //= 2
    if progress is not None:
        progress(1.0)
    return ReachMap(xs, ys, status, float(radius))


def _candidates(robot, model: ArmModel, radius: float, xs: Array, ys: Array, samples: int,
                near: float) -> npt.NDArray[np.bool_]:
    """Cells within ``near`` of the object centre some sampled final configuration holds (in
    either finger when the gripper has two)."""
    rng = np.random.default_rng(0)
    k = rng.uniform(model.lo, model.hi, (samples, model.n))
    pts, th = model.frames(k)
    g = robot.gripper
    normals = [2 * g.g_off + radius] + ([-(2 * g.g_off + radius)] if "right" in g.sides else [])
    held = np.concatenate([pts[:, -1] + complex(g.w_off_along, n) * np.exp(1j * th[:, -1])
                           for n in normals])
    dx = float(xs[1] - xs[0]) if len(xs) > 1 else near
    dy = float(ys[1] - ys[0]) if len(ys) > 1 else near
    ix = np.floor((held.real - xs[0]) / dx + 0.5).astype(int)
    iy = np.floor((held.imag - ys[0]) / dy + 0.5).astype(int)
    px, py = int(np.ceil(near / dx)), int(np.ceil(near / dy))
    candidate = np.zeros((len(ys), len(xs)), bool)
    ok = (ix >= -px) & (ix < len(xs) + px) & (iy >= -py) & (iy < len(ys) + py)
    for ox in range(-px, px + 1):
        for oy in range(-py, py + 1):
            jx, jy = ix[ok] + ox, iy[ok] + oy
            inside = (jx >= 0) & (jx < len(xs)) & (jy >= 0) & (jy < len(ys))
            candidate[jy[inside], jx[inside]] = True
    return candidate


def to_json(reach: ReachMap) -> str:
    """JSON of a map (status rows as digit strings)."""
    return json.dumps({"xs": reach.xs.tolist(), "ys": reach.ys.tolist(), "radius": reach.radius,
                       "status": ["".join(str(int(v)) for v in row) for row in reach.status]})


def from_json(text: str) -> ReachMap:
    """Inverse of :func:`to_json`."""
    d = json.loads(text)
    status = np.array([[int(c) for c in row] for row in d["status"]], np.int8)
    return ReachMap(np.array(d["xs"], float), np.array(d["ys"], float), status,
                    float(d["radius"]))
