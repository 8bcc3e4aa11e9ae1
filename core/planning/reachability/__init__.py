"""Where on the table a grasp can be planned: a grid map for the console's shading.

Every cell centre of a table grid is planned with :func:`core.planning.grasp.plan_grasp` from a
given start (the paper's straight arm by default) for one object radius. To keep the map cheap,
cells that no sampled final configuration comes near (the object centre a configuration holds at
the final radius, arm body clear) are marked unreachable without planning; only the others are
planned. Pure and single-threaded; ``python -m core.planning.reachability``
(:mod:`core.planning.reachability.__main__`) prints a map as JSON (the console runs that in a
low-priority child process, once per robot).
"""

from __future__ import annotations

import dataclasses
import json
from typing import Callable

import numpy as np
import numpy.typing as npt

from core.planning.arm_model import ArmModel
from core.planning.feasibility import GraspRefused
from core.planning.grasp import GraspPlanner
from core.planning.plan_types import PlannerConfig

Array = npt.NDArray[np.float64]

UNREACHABLE, PLANNABLE, FAILS = 0, 1, 2


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
        return float(self.xs[1] - self.xs[0]) if len(self.xs) > 1 else 0.0

    def lookup(self, x: float, y: float) -> int:
        """Status of the cell containing (x, y); UNREACHABLE outside the grid."""
        i = int(round((y - self.ys[0]) / self.step)) if self.step else 0
        j = int(round((x - self.xs[0]) / self.step)) if self.step else 0
        if 0 <= i < len(self.ys) and 0 <= j < len(self.xs):
            return int(self.status[i, j])
        return UNREACHABLE


def reachability_map(robot, radius: float, x_range: tuple[float, float],
                     y_range: tuple[float, float], step: float,
                     kappa_meas: npt.ArrayLike | None = None, samples: int = 40000,
                     near: float = 0.02,
                     should_stop: Callable[[], bool] | None = None) -> ReachMap:
    """Plan an object of ``radius`` at every grid cell (see the module docstring).

    Args:
        robot: A :class:`core.robots.SoftArm`.
        radius: Object radius (m).
        x_range, y_range: Grid extent (m), cell centres from the lower to the upper value.
        step: Cell size (m).
        kappa_meas: Start configuration (default straight).
        samples: Random configurations used to skip cells that are certainly far from reach.
        near: Cells farther than this from every sampled final object position are skipped.
        should_stop: Polled once per planned cell; when it returns True the map is returned
            as far as it got (the remaining cells stay UNREACHABLE).
    """
    if step <= 0 or radius <= 0:
        raise ValueError("step and radius must be positive")
    # Coarser search than an operator's plan (fewer restarts and inserted waypoints): the map
    # is a guide, the plan for a placed object is authoritative.
    cfg = dataclasses.replace(PlannerConfig.from_robot(robot), max_restarts=2, max_insertions=1)
    planner = GraspPlanner(robot, cfg)
    model: ArmModel = planner.model
    km = np.zeros(model.n) if kappa_meas is None else np.asarray(kappa_meas, float)
    xs = np.arange(x_range[0], x_range[1] + 0.5 * step, step)
    ys = np.arange(y_range[0], y_range[1] + 0.5 * step, step)
    status = np.zeros((len(ys), len(xs)), np.int8)
    # Object centres held at the final radius by random configurations whose body is clear.
    rng = np.random.default_rng(0)
    k = rng.uniform(model.lo, model.hi, (samples, model.n))
    pts, th = model.frames(k)
    g = robot.gripper
    held = pts[:, -1] + complex(g.w_off_along, 2 * g.g_off + radius) * np.exp(1j * th[:, -1])
    ix = np.floor((held.real - xs[0]) / step + 0.5).astype(int)
    iy = np.floor((held.imag - ys[0]) / step + 0.5).astype(int)
    pad = int(np.ceil(near / step))
    candidate = np.zeros_like(status, bool)
    ok = (ix >= -pad) & (ix < len(xs) + pad) & (iy >= -pad) & (iy < len(ys) + pad)
    for dx in range(-pad, pad + 1):
        for dy in range(-pad, pad + 1):
            jx, jy = ix[ok] + dx, iy[ok] + dy
            inside = (jx >= 0) & (jx < len(xs)) & (jy >= 0) & (jy < len(ys))
            candidate[jy[inside], jx[inside]] = True
    for i, j in zip(*np.nonzero(candidate)):
        if should_stop is not None and should_stop():
            break
        try:
            plan = planner.plan(km, (xs[j], ys[i]), radius)
        except GraspRefused:
            continue
        status[i, j] = PLANNABLE if plan.success else FAILS
    return ReachMap(xs, ys, status, float(radius))


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
