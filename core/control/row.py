"""Several objects in a row (issue #17.3): a queue over the Fig. 3 machine, one object after another.

The paper's state machine (:mod:`core.control.grasp_place`) handles one object: settle, plan,
approach, grasp, move to the bin, release. :class:`ObjectRow` keeps a queue of objects and,
after every control tick, looks at the machine: when it has ``released`` the current object at
the bin, the next one starts (``ControlStack.start``: settle -> plan -> approach -> grasp ->
move_to_bin -> release) until the queue is empty. When the machine *stops* on an object
(planner refusal, tracking lost, grasp missed too often, bin not reached, a per-object time
limit), that object is recorded as failed with the machine's reason and the row goes on with
the next object. Only the operator's STOP (:meth:`ObjectRow.stop`) or a disarmed stack ends the
row early; the objects not tried are recorded as skipped, with that reason. (The operator's STOP
must go through :meth:`ObjectRow.stop`: a stop the row does not know of looks like a failure
of the current object, and the row would go on.) A bin given to the row is the machine's for
that row only. With obstacles (``stack.set_obstacles``) every object's carry to the bin keeps
their clearance (:mod:`core.control.carry`), and a bin too close to one is refused at the start.
The objects not yet moved are obstacles too: while object k is taken, every plan (the first,
every re-plan and the carry) keeps the machine's clearance from objects k+1 .. N (each a disk of
its radius, named "object j" by its place in the queue; :func:`row_obstacles`), so the arm never
sweeps through an object still waiting on the table; a bin pose too close to one of them is
refused at the start. The objects already taken (released, or failed and possibly moved) are
not. An object whose plan is refused because of a waiting object (its approach or its carry
blocked by "object j") waits, once, behind the rest of the queue: taking the others first
clears its way (the order a person would choose). The machine's own obstacles are put back
when the row ends.

The row is pure bookkeeping, called from the loop thread (the only one that touches the stack):
:meth:`ObjectRow.start` and :meth:`ObjectRow.after_tick` return the object whose turn begins, so
the caller can put it into a simulated world (the simulator holds one object at a time);
:func:`run_row` drives a :class:`core.control.sim_loop.SimLoop` that way. :func:`bin_at` turns a
bin placed on the table (a point) into the configuration ``move_to_bin`` goes to.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Callable, Sequence
from typing import Any, Literal

import numpy as np

from core.control.carry import check_bin
from core.control.grasp_place import Phase
from core.control.params import BinParams, StateMachineParams
from core.planning.obstacles import Obstacle, with_other_objects
from core.robots import SoftArm

RowState = Literal["idle", "running", "done", "stopped"]
Status = Literal["released", "failed", "skipped"]


@dataclasses.dataclass(frozen=True)
class RowObject:
    """One object of the queue: centre ``(x, y)`` and radius ``r`` on the table (m)."""

    x: float
    y: float
    r: float

    def __post_init__(self) -> None:
        if not all(math.isfinite(v) for v in (self.x, self.y, self.r)) or self.r <= 0:
            raise ValueError(f"object ({self.x}, {self.y}) radius {self.r}: need finite x, y "
                             "and a radius > 0 (m)")


@dataclasses.dataclass(frozen=True)
class ObjectOutcome:
    """What became of one object of the row (times are simulated/loop seconds)."""

    index: int  # 0-based position in the queue
    object: RowObject
    status: Status
    reason: str | None  # None when released
    started_s: float | None = None
    ended_s: float | None = None
    approach_s: float | None = None
    return_s: float | None = None
    replans: int = 0

    @property
    def released(self) -> bool:
        return self.status == "released"


def row_obstacles(obstacles: Sequence[Any], objects: Sequence[RowObject],
                  index: int, waiting: Sequence[int] | None = None) -> tuple[Obstacle, ...]:
    """What the plans for ``objects[index]`` keep the clearance from: ``obstacles`` and the
    objects still waiting on the table (``waiting``, queue places; default: the objects after
    ``index``), named "object j" (1-based queue place)."""
    later = set(range(index + 1, len(objects)) if waiting is None else waiting) - {index}
    blockers = [Obstacle(f"object {j + 1}", o.x, o.y, o.r)
                for j, o in enumerate(objects) if j in later]
    return with_other_objects(tuple(obstacles), blockers)


_WAITING_OBJECT = re.compile(r"\bobject \d+\b")


def blocked_by_waiting(reason: str | None) -> bool:
    """Whether the machine stopped because its plan was refused for a waiting object (the
    planner names it "object j": an approach or a carry that would pass through it)."""
    return bool(reason and reason.startswith("planner refused")
                and _WAITING_OBJECT.search(reason))


class ObjectRow:
    """A queue of objects taken to one bin, one after another, over a control stack's machine.

    Args:
        objects: The queue, in the order the arm takes them (at least one).
        bin_params: Where ``move_to_bin`` goes; None keeps the robot's ``[bin]``.
        object_time_limit_s: An object still not released this long after its start fails
            with that reason (None: only the machine's own timeouts apply).
        check_release: Optional ``object -> reason or None`` called when the machine says
            ``released`` (e.g. the trials check the object really lies at the bin); a reason
            turns the outcome into a failure.
    """

    def __init__(self, objects: Sequence[RowObject], bin_params: BinParams | None = None,
                 object_time_limit_s: float | None = None,
                 check_release: Callable[[RowObject], str | None] | None = None):
        self.objects = tuple(objects)
        if not self.objects:
            raise ValueError("a row needs at least one object")
        if object_time_limit_s is not None and not object_time_limit_s > 0:
            raise ValueError(f"object_time_limit_s must be > 0, got {object_time_limit_s}")
        self.bin_params = bin_params
        self.object_time_limit_s = object_time_limit_s
        self.check_release = check_release
        self.state: RowState = "idle"
        self.current: int | None = None
        self.outcomes: list[ObjectOutcome] = []
        self.reason: str | None = None
        self._started_s = 0.0
        self._robot_bin: BinParams | None = None  # the machine's bin before the row
        self._queue: list[int] = []  # queue places of the objects not yet begun, in turn
        self._deferred: set[int] = set()  # objects that waited behind the others once
        self._obstacles: tuple[Any, ...] = ()  # the machine's obstacles before the row

    # -- progress ------------------------------------------------------------------------------
    @property
    def released(self) -> int:
        return sum(o.released for o in self.outcomes)

    def progress(self) -> str:
        """``"object 2 of 3"`` while running, else e.g. ``"2/3 released"``."""
        n = len(self.objects)
        if self.state == "running" and self.current is not None:
            return f"object {self.current + 1} of {n}"
        return f"{self.released}/{n} released"

    # -- the loop thread's calls ---------------------------------------------------------------
    def start(self, stack: Any, t: float) -> RowObject:
        """Start the first object (the stack must be armed); returns it."""
        if self.state != "idle":
            raise RuntimeError(f"the row was already started ({self.state})")
        if not stack.armed:
            raise RuntimeError("row refused: the arm is not armed")
        m = stack.machine  # a bin too close to an obstacle or to an object not yet moved
        # when an object is taken: ValueError before anything changes (the first object's
        # obstacles include every later one's)
        self._obstacles = tuple(getattr(m, "obstacles", ()))
        check_bin(m.robot, m.bin if self.bin_params is None else self.bin_params,
                  row_obstacles(self._obstacles, self.objects, 0), getattr(m, "clearance", 0.0))
        self._robot_bin = stack.machine.bin
        if self.bin_params is not None:
            stack.machine.bin = self.bin_params  # for this row only: put back when it ends
        self.state = "running"
        self._queue = list(range(1, len(self.objects)))
        return self._begin(stack, 0, t)

    def _begin(self, stack: Any, index: int, t: float) -> RowObject:
        self.current = index
        self._started_s = t
        self._set_obstacles(stack, row_obstacles(self._obstacles, self.objects, index,
                                                 self._queue))
        stack.start(t)
        return self.objects[index]

    @staticmethod
    def _set_obstacles(stack: Any, obstacles: tuple[Any, ...]) -> None:
        """The machine's obstacles (its clearance kept), for its first plan and re-plans."""
        m = stack.machine
        if hasattr(m, "set_obstacles"):
            m.set_obstacles(obstacles, getattr(m, "clearance", 0.0))

    def _record(self, stack: Any, status: Status, reason: str | None, t: float) -> None:
        m = stack.machine
        assert self.current is not None
        self.outcomes.append(ObjectOutcome(
            self.current, self.objects[self.current], status, reason, self._started_s, t,
            m.approach_s, m.return_s, m.replans))
        self.outcomes.sort(key=lambda o: o.index)  # queue order, whichever waited

    def after_tick(self, stack: Any, t: float) -> RowObject | None:
        """Look at the machine after a tick at ``t``; returns the next object if one starts."""
        if self.state != "running":
            return None
        m = stack.machine
        if not stack.armed:  # a device fault disarmed the stack: nothing more moves
            self._end(stack, "stopped", m.reason or "the arm was disarmed", t)
            return None
        if m.phase is Phase.IDLE:  # the machine was reset under the row (re-armed, a goto)
            self._end(stack, "stopped", "the grasp-and-place task was reset", t)
            return None
        limit = self.object_time_limit_s
        if m.phase not in (Phase.RELEASED, Phase.STOPPED) and limit is not None \
                and t - self._started_s >= limit:
            m.stop(t, f"time limit {limit:g} s reached in {m.phase.value}")
        if m.phase is Phase.RELEASED:
            obj = self.objects[self.current]  # type: ignore[index]
            why = self.check_release(obj) if self.check_release else None
            self._record(stack, "failed" if why else "released", why, t)
        elif m.phase is Phase.STOPPED:
            cur = self.current
            if (cur is not None and self._queue and cur not in self._deferred
                    and blocked_by_waiting(m.reason)):
                self._deferred.add(cur)  # its way is blocked: take the others first
                self._queue.append(cur)
            else:
                self._record(stack, "failed", m.reason or "stopped", t)
        else:
            return None
        if not self._queue:
            self.state, self.current = "done", None
            stack.machine.bin = self._robot_bin
            self._set_obstacles(stack, self._obstacles)
            return None
        return self._begin(stack, self._queue.pop(0), t)

    def stop(self, stack: Any, t: float, reason: str = "operator STOP") -> None:
        """The operator's STOP: hold the arm and end the row; the rest is skipped with ``reason``."""
        stack.stop(t, reason)
        if self.state in ("idle", "running"):
            self._end(stack, "stopped", reason, t)

    def _end(self, stack: Any, state: RowState, reason: str, t: float) -> None:
        if self.state == "running" and self.current is not None:
            self._record(stack, "failed", reason, t)
        done = {o.index for o in self.outcomes}
        self.outcomes += [ObjectOutcome(i, o, "skipped", f"row stopped: {reason}")
                          for i, o in enumerate(self.objects) if i not in done]
        self.state, self.current, self.reason = state, None, reason
        if self._robot_bin is not None:
            stack.machine.bin = self._robot_bin
            self._set_obstacles(stack, self._obstacles)


def run_row(loop: Any, row: ObjectRow, place: Callable[[RowObject], None],
            time_limit_s: float, observe: Callable[[Any], Any] | None = None) -> ObjectRow:
    """Drive ``row`` on a :class:`~core.control.sim_loop.SimLoop` that is armed already.

    ``place(obj)`` puts each object into the simulated world when its turn begins (the first
    before the row starts). Ticks until the row is done or ``time_limit_s`` of simulated time
    passed (then the row is stopped with that reason). ``observe(telemetry)`` sees every tick.
    """
    place(row.objects[0])
    loop.submit(lambda s, t: row.start(s, t))
    n = round(time_limit_s * 1e9 / loop.period_ns)
    for _ in range(max(1, n)):
        t = loop.t
        control = loop.tick()
        if observe is not None:
            observe(control)
        nxt = row.after_tick(loop.stack, t)
        if nxt is not None:
            place(nxt)
        if row.state not in ("idle", "running"):
            return row
    row.stop(loop.stack, loop.t, f"row time limit {time_limit_s:g} s reached")
    return row


def bin_drop_point(robot: SoftArm, kappa: Any, radius: float,
                   side: Literal["left", "right"] = "left") -> np.ndarray:
    """Where an object of ``radius`` held in the gripper by the ``side`` finger sits with the
    arm at ``kappa`` (m)."""
    from core.kinematics.planar import forward_kinematics, point_in_frame
    tip = forward_kinematics(np.asarray(kappa, dtype=float), robot.lengths, robot.base_pose)[-1]
    normal = 2 * robot.gripper.g_off + radius
    return np.asarray(point_in_frame(tip, (robot.gripper.w_off_along,
                                           -normal if side == "right" else normal)), dtype=float)


def bin_at(robot: SoftArm, x: float, y: float, radius: float | None = None) -> BinParams:
    """The bin placed at ``(x, y)`` on the table, as the configuration ``move_to_bin`` goes to.

    The configuration is the grasp planner's final pose for an object of ``radius`` (default
    the robot's nominal object) lying at the bin: with the arm there, the held object is over
    the bin point, so releasing it drops it there. Only the final pose is needed (the arm moves
    to the bin directly, not along an approach), so a plan whose approach failed still gives a
    bin when its final pose was solved. A gripper with fingers on both sides gets one pose per
    finger (``kappa_right``: the right finger's object over the point, planned by mirroring,
    :mod:`core.planning.sides`), so an object grasped on either side drops at the bin. Raises
    ValueError with the reason when no pose puts a finger over the point (out of reach, on the
    base, on the straight arm).
    """
    r = robot.capture.nominal_object_radius if radius is None else float(radius)
    where = f"({x * 1000:.0f}, {y * 1000:.0f}) mm"
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(r) and r > 0):
        raise ValueError(f"bin at {where}: need a finite point and an object radius > 0")
    kappa = _bin_pose(robot, x, y, r, "left", where)
    kappa_right = (_bin_pose(robot, x, y, r, "right", where)
                   if "right" in robot.gripper.sides else None)
    return BinParams(kappa, robot.bin.drop_radius_m, kappa_right)


def _bin_pose(robot: SoftArm, x: float, y: float, r: float, side: Literal["left", "right"],
              where: str) -> np.ndarray:
    """The final pose of a ``side``-finger grasp of an object of radius ``r`` at ``(x, y)``."""
    from core.planning.grasp import GraspRefused
    from core.planning.sides import plan_grasp_sided
    finger = "" if side == "left" or "left" not in robot.gripper.sides else "the right finger: "
    try:
        plan = plan_grasp_sided(robot, np.zeros(robot.n_segments), (x, y), r, side=side)
    except GraspRefused as exc:
        raise ValueError(f"{finger}{exc.about(f'bin at {where}')}") from None
    if len(plan.status) == 0 or plan.status[-1] != "ok":
        raise ValueError(f"the bin at {where} cannot be reached: {finger}no arm shape puts the "
                         "gripper over it")
    kappa = np.asarray(plan.kappas[-1], dtype=float)
    miss = float(np.hypot(*(bin_drop_point(robot, kappa, r, side) - (x, y))))
    tol = StateMachineParams.from_robot(robot).release_distance_m
    if miss > tol:  # the solver's palm-point error is far below this
        raise ValueError(f"the bin at {where} cannot be reached: {finger}the closest pose drops "
                         f"{miss * 1000:.0f} mm away")
    return kappa
