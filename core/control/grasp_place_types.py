"""What the grasp-and-place machine (:mod:`core.control.grasp_place`) takes and gives: its
phases, the plan request and the planner interface, the per-tick observation and decision.

Kept apart from the machine so the planner process, the control stack and the tests can speak
its language without reading the step logic; ``grasp_place`` re-exports every name.
"""

from __future__ import annotations

import dataclasses
import enum
from typing import Any, Callable, Protocol

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]


class Phase(str, enum.Enum):
    """States of Fig. 3 plus idle/stopped."""

    IDLE = "idle"
    SETTLING = "settling"
    PLANNING = "planning"
    APPROACH = "approach"
    GRASP = "grasp"
    MOVE_TO_BIN = "move_to_bin"
    RELEASE = "release"
    RELEASED = "released"
    STOPPED = "stopped"


MOVING = (Phase.APPROACH, Phase.GRASP, Phase.MOVE_TO_BIN, Phase.RELEASE)


@dataclasses.dataclass(frozen=True)
class PlanRequest:
    """What the planner needs: measured curvatures, object centre and radius, and the obstacles
    (``core.planning.obstacles.Obstacle``) every plan keeps ``clearance`` (m) from; with
    obstacles the bin (``BinParams``) the carry goes to, and ``plan`` when the grasp is given
    (only its carry is planned, :func:`core.control.planner_spec.plan_request`)."""

    kappa: Array
    center: Array
    radius: float
    obstacles: tuple[Any, ...] = ()
    clearance: float = 0.0
    bin: Any = None
    plan: Any = None


@dataclasses.dataclass(frozen=True)
class WaypointPlan:
    """The part of a ``GraspPlan`` the machine executes: waypoints (n, N), palm poses (n, 3)
    and the carry to the bin (``GraspPlan.carry``)."""

    kappas: Array
    palm_poses: Array
    carry: Array | None = None


class PlanHandle(Protocol):
    def done(self) -> bool: ...

    def result(self) -> Any: ...


Planner = Callable[[PlanRequest], PlanHandle]


class _Done:
    def __init__(self, value: Any = None, error: BaseException | None = None):
        self._value, self._error = value, error

    def done(self) -> bool:
        return True

    def result(self) -> Any:
        if self._error is not None:
            raise self._error
        return self._value


def immediate(fn: Callable[[PlanRequest], Any]) -> Planner:
    """A planner that runs ``fn`` synchronously (sim clock, tests); errors surface in result()."""
    def plan(req: PlanRequest) -> PlanHandle:
        try:
            return _Done(fn(req))
        except Exception as exc:  # noqa: BLE001 - handed to the state machine as a reason
            return _Done(error=exc)
    return plan


@dataclasses.dataclass(frozen=True)
class Observation:
    """Per-tick input. ``kappa`` None: tracking lost; ``object_xy`` None: object not seen."""

    t: float
    kappa: Array | None
    object_xy: Array | None
    object_radius: float | None
    reference_finished: bool = True


@dataclasses.dataclass(frozen=True)
class Decision:
    """Per-tick output for the control stack.

    ``kappa_target``: new trajGen target (None: keep); ``hold_reference``: stop the reference
    where it is (closed loop holds it); ``freeze``: hold the cylinder volumes (no feedback).
    """

    phase: Phase
    kappa_target: Array | None = None
    gripper_closed: bool = False
    hold_reference: bool = False
    freeze: bool = False
    reason: str | None = None
