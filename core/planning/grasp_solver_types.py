"""What the grasp SQP (:mod:`core.planning.grasp_solver`) takes and gives back: status codes,
options, the result of one waypoint solve, and its inequality-constraint sets.

The constraint-set protocol (``size``, ``evaluate``, ``jacobian``) is what obstacle disks
(:mod:`core.planning.obstacles`) implement too; ``grasp_solver`` re-exports every name.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import numpy.typing as npt

from core.planning.arm_model import ArmModel

Array = npt.NDArray[np.float64]

OK, NO_CONVERGENCE, CURVATURE_LIMIT, CLEARANCE = 0, 1, 2, 3
STATUS_NAMES = ("ok", "no_convergence", "curvature_limit", "clearance")


@dataclasses.dataclass(frozen=True)
class SolverOptions:
    """Tolerances and limits; the defaults converge far below the paper's 2e-3 tolerance."""

    max_iter: int = 40
    ctol: float = 1e-8           # m, equality violation counted as converged
    xtol: float = 1e-8           # 1/m, last step size counted as converged
    gtol: float = 1e-6           # relative Lagrangian-gradient norm counted as converged
    max_qp_iter: int = 12
    armijo: float = 1e-4
    min_alpha: float = 1e-4
    clearance_tol: float = 1e-9  # m
    max_step: float = 16.0       # 1/m, longest curvature step per iteration (damping)


@dataclasses.dataclass
class SolveResult:
    """Result of one waypoint solve."""

    kappa: Array
    lam: tuple[float, float]  # multipliers of the two palm-point equalities
    status: int               # OK / NO_CONVERGENCE / CURVATURE_LIMIT / CLEARANCE
    iterations: int
    violation: float          # max |palm point - circle point| (m)
    cost: float
    active: tuple[int, ...]   # per kappa: -1 at the lower bound, +1 at the upper, 0 free
    error: complex = 0j                    # q - c: object-centre point error (complex)
    dkappa_dr: Array | None = None         # sensitivity of the solution to the circle radius
    dlam_dr: tuple[float, float] | None = None

    @property
    def ok(self) -> bool:
        return self.status == OK


@dataclasses.dataclass(frozen=True)
class Clearance:
    """Arm-body clearance constraints: every segment's arc stays >= rho from ``center``.

    A constraint set gives the solver ``size(n)`` rows h(kappa) >= 0: ``evaluate`` returns
    their values (array) and what ``jacobian`` needs again (the closest points' arc lengths);
    ``jacobian`` returns the rows dh/dkappa as lists. :class:`Constraints` joins several sets.
    """

    center: complex
    rho: float

    def size(self, n: int) -> int:
        return n

    def evaluate(self, model: ArmModel, x: list[float]) -> tuple[Array, Array]:
        dist, sstar = model.arc_distances(np.array(x)[None], self.center)
        return dist[0] - self.rho, sstar

    def jacobian(self, model: ArmModel, x: list[float], aux: Array) -> list[list[float]]:
        pts, Jp = model.arc_points(np.array(x)[None], aux)
        u = pts[0] - self.center
        u = np.conj(u / np.maximum(np.abs(u), 1e-12))
        return (u[:, None] * Jp[0]).real.tolist()


@dataclasses.dataclass(frozen=True)
class Constraints:
    """Several constraint sets (e.g. object clearance and obstacles) as one."""

    parts: tuple

    def size(self, n: int) -> int:
        return sum(p.size(n) for p in self.parts)

    def evaluate(self, model: ArmModel, x: list[float]) -> tuple[Array, list]:
        out = [p.evaluate(model, x) for p in self.parts]
        return np.concatenate([h for h, _ in out]), [a for _, a in out]

    def jacobian(self, model: ArmModel, x: list[float], aux: list) -> list[list[float]]:
        return [row for p, a in zip(self.parts, aux) for row in p.jacobian(model, x, a)]


def joined(*sets):
    """The constraint sets that are not None, as one set (None when there are none)."""
    parts = tuple(s for s in sets if s is not None)
    return None if not parts else parts[0] if len(parts) == 1 else Constraints(parts)
