"""Every command the console sends to an arm's control loop, as one small frozen dataclass each.

GUI callbacks only build one of these and enqueue it; the loop thread (the only writer to the
hardware) applies it at its next tick and dispatches on its type. They cross the soft arm's
process pipe as they are (plain fields: picklable), and go straight into the extensible runner's
queue. Grouped by who understands them:

* :data:`BridgeCommand` -- the Hardware panel's link verbs, the same for both arms
  (:class:`hw_bridge.link_supervisor.LinkSupervisor` runs them);
* :data:`SoftArmCommand` -- the soft arm's control stack (Control panel, grasp planner);
* :data:`ExtensibleCommand` -- the extensible arm's streamer (paths, moves, STOP).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any, Union

if TYPE_CHECKING:
    from core.planning.paths import MotionPath


# -- the link (both arms) ------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Connect:
    """Close the link and open ``port`` at ``baud`` (0: unchanged); configured, not armed."""

    port: str = ""
    baud: int = 0


@dataclasses.dataclass(frozen=True)
class Disconnect:
    """Stop commanding, DISARM and close the port; Arm is refused until a Connect."""


@dataclasses.dataclass(frozen=True)
class Arm:
    """Activate the link (configuring first if needed) and hold where the arm is."""


@dataclasses.dataclass(frozen=True)
class Disarm:
    """Stop commanding and DISARM; telemetry goes on."""


BridgeCommand = Union[Connect, Disconnect, Arm, Disarm]
BRIDGE_COMMANDS = (Connect, Disconnect, Arm, Disarm)


# -- the soft arm's control stack ----------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Goto:
    """Move to curvatures ``q`` (1/m, one per segment) when no task runs."""

    q: tuple[float, ...]


@dataclasses.dataclass(frozen=True)
class StopArm:
    """Controlled stop: hold, abort the task with ``reason`` (the operator's STOP)."""

    reason: str = "operator STOP"


@dataclasses.dataclass(frozen=True)
class StartGrasp:
    """Start the grasp-and-place task for the placed object."""


@dataclasses.dataclass(frozen=True)
class PlaceObject:
    """Put the (simulated) object at ``(x, y)`` with radius ``r`` (m)."""

    x: float
    y: float
    r: float


ObstacleRow = tuple[str, float, float, float]  # an obstacle disk: name, x, y, r (m)


@dataclasses.dataclass(frozen=True)
class GraspAt:
    """Place the object at ``(x, y)`` (radius ``r``), arm if needed and run the grasp task.

    ``obstacles`` (name, x, y, r each) are what every plan of the task -- the first and every
    re-plan -- keeps ``clearance`` (m) from (the Objects panel's; the same on the commands
    below)."""

    x: float
    y: float
    r: float
    obstacles: tuple[ObstacleRow, ...] = ()
    clearance: float = 0.0
    bin_kappa: tuple[float, ...] = ()        # the bin placed on the table (empty: the robot's)
    bin_kappa_right: tuple[float, ...] = ()  # its right finger's pose (empty: bin_kappa)


@dataclasses.dataclass(frozen=True)
class ExecutePlan:
    """Place the object at ``(x, y)`` (radius ``r``), arm if needed and run a planner's plan:
    ``kappas`` (K, n) waypoint curvatures, ``palms`` (K, 3) palm poses."""

    kappas: tuple[tuple[float, ...], ...]
    palms: tuple[tuple[float, ...], ...]
    x: float
    y: float
    r: float
    obstacles: tuple[ObstacleRow, ...] = ()  # the plan's: its re-plans keep clear of them too
    clearance: float = 0.0
    bin_kappa: tuple[float, ...] = ()        # as GraspAt's
    bin_kappa_right: tuple[float, ...] = ()


@dataclasses.dataclass(frozen=True)
class RunRow:
    """Take every object of ``objects`` (``(x, y, r)`` each, m, in this order) to the bin, one
    after another (:class:`core.control.row_stack.RowControlStack`); the arm must be armed.

    ``bin_kappa`` is the configuration ``move_to_bin`` goes to for this row (the bin placed at
    ``bin_xy`` on the table, :func:`core.control.row.bin_at`), ``bin_kappa_right`` the one for
    an object the right finger holds (empty: ``bin_kappa``). ``row_id`` names the row in the
    published reports. Every object's plans keep ``clearance`` from ``obstacles``.
    """

    row_id: int
    objects: tuple[tuple[float, float, float], ...]
    bin_xy: tuple[float, float]
    bin_kappa: tuple[float, ...]
    bin_kappa_right: tuple[float, ...] = ()
    obstacles: tuple[ObstacleRow, ...] = ()
    clearance: float = 0.0


def obstacle_rows(obstacles: Any) -> tuple[ObstacleRow, ...]:
    """``core.planning.obstacles.Obstacle`` disks (or (name, x, y, r) rows) as a command's
    plain rows."""
    out = []
    for o in obstacles or ():
        name, x, y, r = (o.name, o.x, o.y, o.r) if hasattr(o, "name") else o
        out.append((str(name), float(x), float(y), float(r)))
    return tuple(out)


def bin_rows(bin_params: Any) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """A placed bin (``core.control.params.BinParams``; None: none) as a command's
    ``bin_kappa`` and ``bin_kappa_right`` rows (empty: the robot's bin; the left pose)."""
    if bin_params is None:
        return (), ()
    def flat(k: Any) -> tuple[float, ...]:
        return () if k is None else tuple(float(v) for v in k)
    return flat(bin_params.kappa), flat(getattr(bin_params, "kappa_right", None))


def obstacles_of(cmd: Any) -> list[Any]:
    """The obstacles of a :class:`GraspAt`, :class:`ExecutePlan` or :class:`RunRow` as
    ``core.planning.obstacles.Obstacle`` disks (the planner checks them and says what is wrong)."""
    from core.planning.obstacles import Obstacle
    return [Obstacle(*row) for row in cmd.obstacles]


SoftArmCommand = Union[BridgeCommand, Goto, StopArm, StartGrasp, PlaceObject, GraspAt,
                       ExecutePlan, RunRow]
SCENE_COMMANDS = (PlaceObject, GraspAt, ExecutePlan)  # they put the object into the world first


# -- the extensible arm's streamer ---------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class RunPath:
    """Stream ``path``'s motor counts (after a joint move to its first sample) as job ``job_id``."""

    job_id: int
    label: str
    path: MotionPath


@dataclasses.dataclass(frozen=True)
class Hold:
    """Hold position where the motors are (aborts the running job)."""


@dataclasses.dataclass(frozen=True)
class ConnectFactory:
    """Reconnect to the runner's hardware factory and configure it, disarmed (only the
    operator's :class:`Arm` arms)."""


@dataclasses.dataclass(frozen=True)
class CloseLink:
    """DISARM and close the link (the runner is shutting down)."""


@dataclasses.dataclass(frozen=True)
class Setpoint:
    """The console's newest commanded posture (``seq`` of the command, Delta (n, 3)), followed
    while idle; sent to the extensible arm's process whenever the command changes."""

    seq: int
    delta: tuple[tuple[float, ...], ...]


ExtensibleCommand = Union[BridgeCommand, RunPath, Hold, ConnectFactory, CloseLink, Setpoint]
