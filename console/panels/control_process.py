"""The soft arm's 100 Hz loop in its own process, so the console's threads cannot delay it.

In the console process the render thread, viser's event loop and the panels hold the GIL for
milliseconds at a time (mesh updates, plot serialisation): a 100 Hz loop *thread* there misses
deadlines (measured: hundreds of overruns per minute, p99 period error tens of ms on 2 cores).
:class:`ControlProcess` therefore runs the simulated arm, the control stack and the real-time
:class:`hw_bridge.loop.LoopRunner` thread in a spawned child process (planning in a further
:class:`hw_bridge.loop.ProcessPlanner` process). The console talks to it with small messages:

* commands go down a queue (``("arm",)``, ``("goto", q)``, ``("grasp_at", x, y, r)``, ...), are
  applied by the child's loop thread at its next tick, and each returns a Future that the reply
  resolves (with the loop's error, if it refused);
* the child publishes a :class:`ControlView` (the loop snapshot, recent stats, the true object
  and the gripper finger for drawing) at ``publish_hz``; :attr:`ControlProcess.view` is the newest
  one (a reference swap, no lock for readers).
"""

from __future__ import annotations

import atexit
import concurrent.futures as cf
import dataclasses
import itertools
import multiprocessing
import queue
import threading
from typing import Any

import numpy as np

from hw_bridge.loop import LoopSnapshot, LoopStats


@dataclasses.dataclass(frozen=True)
class ControlView:
    """What the console draws: loop snapshot, stats and the simulated scene."""

    snapshot: LoopSnapshot
    stats: LoopStats
    scheduling: str
    object_xy: tuple[float, float] | None
    object_radius: float | None
    captured: bool
    finger: np.ndarray | None  # (M, 2) gripper centreline in the world while closing


def _child(robot_source: str, seed: int, commands: Any, replies: Any, publish_hz: float,
           stats_ticks: int, sched_priority: int | None) -> None:
    from core.control.sim import SoftArmSim
    from core.control.stack import ControlStack
    from core.robots import load
    from hw_bridge.loop import LoopRunner, ProcessPlanner, SimDevice

    robot = load(robot_source)
    sim = SoftArmSim(robot, seed=seed)
    planner = ProcessPlanner(robot_source)
    stack = ControlStack(robot, 0.01, planner)
    runner = LoopRunner(SimDevice(sim), stack, 0.01)

    def grasp_at(s: ControlStack, t: float, x: float, y: float, r: float) -> None:
        sim.place_object(x, y, r)
        if not s.armed:
            s.arm(sim.cylinders.copy())
        s.start(t)

    def execute(s: ControlStack, t: float, kappas: list, palms: list, x: float, y: float,
                r: float) -> None:
        from core.control.grasp_place import WaypointPlan
        sim.place_object(x, y, r)
        if not s.armed:
            s.arm(sim.cylinders.copy())
        s.execute(WaypointPlan(np.asarray(kappas, float), np.asarray(palms, float)), (x, y), t)

    actions = {
        "execute": execute,
        "arm": lambda s, t: s.arm(sim.cylinders.copy()),
        "disarm": lambda s, t: s.disarm(),
        "goto": lambda s, t, q: s.goto(np.asarray(q, float), t),
        "stop": lambda s, t, reason: s.stop(t, reason),
        "start": lambda s, t: s.start(t),
        "place_object": lambda s, t, x, y, r: sim.place_object(x, y, r),
        "grasp_at": grasp_at,
    }
    stop = threading.Event()

    def publish() -> None:
        while not stop.wait(1.0 / publish_hz):
            obj = sim.obj
            finger = sim.gripper_polyline() if sim.turn > 1e-3 else None
            view = ControlView(runner.snapshot, runner.stats(last=stats_ticks), runner.scheduling,
                               None if obj is None else (float(obj.xy[0]), float(obj.xy[1])),
                               None if obj is None else obj.radius, sim.captured, finger)
            replies.put(("view", view))

    runner.start(sched_priority=sched_priority)
    pub = threading.Thread(target=publish, name="control-publish", daemon=True)
    pub.start()
    try:
        parent = multiprocessing.parent_process()
        while True:
            try:
                msg = commands.get(timeout=1.0)
            except queue.Empty:
                if parent is not None and not parent.is_alive():
                    break  # the console went away: stop the arm's loop too
                continue
            if msg is None:
                break
            cid, name, args = msg
            fn = actions.get(name)
            if fn is None:
                replies.put(("reply", cid, f"unknown command {name!r}"))
                continue
            fut = runner.submit(lambda s, t, fn=fn, args=args: fn(s, t, *args))
            fut.add_done_callback(lambda f, cid=cid: replies.put(
                ("reply", cid, None if f.exception() is None else str(f.exception()))))
    finally:
        stop.set()
        runner.stop()
        pub.join(2.0)
        planner.close()
        del runner, stack, actions  # free ruckig objects before interpreter teardown


class ControlProcess:
    """Parent-side handle of the child control process (see the module docstring).

    Args:
        robot: The soft arm (its ``source`` file is loaded in the child).
        seed: Seed of the simulated arm.
        publish_hz: How often the child sends a :class:`ControlView`.
        sched_priority: ``SCHED_FIFO`` priority for the loop thread (None: normal scheduling;
            refused without the permission, which the view's ``scheduling`` reports).
    """

    def __init__(self, robot: Any, seed: int = 0, publish_hz: float = 30.0,
                 stats_ticks: int = 1000, sched_priority: int | None = 50):
        ctx = multiprocessing.get_context("spawn")
        self.robot = robot
        self._commands = ctx.Queue()
        self._replies = ctx.Queue()
        # Not a daemon: it starts its own planner process. close() (also at exit) ends it.
        self._proc = ctx.Process(target=_child, name="soft-arm-control",
                                 args=(str(robot.source), seed, self._commands, self._replies,
                                       publish_hz, stats_ticks, sched_priority))
        self._proc.start()
        self._ids = itertools.count(1)
        self._pending: dict[int, cf.Future] = {}
        self._lock = threading.Lock()
        self.view: ControlView | None = None
        self._reader = threading.Thread(target=self._read, name="control-replies", daemon=True)
        self._reader.start()
        atexit.register(self.close)

    def _read(self) -> None:
        while True:
            try:
                msg = self._replies.get(timeout=1.0)
            except queue.Empty:
                if not self._proc.is_alive():
                    return
                continue
            except (EOFError, OSError):
                return
            if msg[0] == "view":
                self.view = msg[1]
            elif msg[0] == "reply":
                with self._lock:
                    fut = self._pending.pop(msg[1], None)
                if fut is not None:
                    if msg[2] is None:
                        fut.set_result(None)
                    else:
                        fut.set_exception(RuntimeError(msg[2]))

    def send(self, name: str, *args: Any) -> cf.Future:
        """Queue a command for the loop; the Future resolves when the loop applied it."""
        fut: cf.Future = cf.Future()
        if not self._proc.is_alive():
            fut.set_exception(RuntimeError("the control process is not running"))
            return fut
        cid = next(self._ids)
        with self._lock:
            self._pending[cid] = fut
        self._commands.put((cid, name, tuple(args)))
        return fut

    def arm(self) -> cf.Future:
        return self.send("arm")

    def disarm(self) -> cf.Future:
        return self.send("disarm")

    def goto(self, q: Any) -> cf.Future:
        return self.send("goto", [float(v) for v in np.asarray(q).ravel()])

    def stop_arm(self, reason: str = "operator STOP") -> cf.Future:
        return self.send("stop", reason)

    def place_object(self, x: float, y: float, r: float) -> cf.Future:
        return self.send("place_object", float(x), float(y), float(r))

    def grasp_at(self, x: float, y: float, r: float) -> cf.Future:
        return self.send("grasp_at", float(x), float(y), float(r))

    def execute(self, plan: Any, x: float, y: float, r: float) -> cf.Future:
        """Place the object at (x, y) and run ``plan`` (a GraspPlan for it), then place it."""
        return self.send("execute", np.asarray(plan.kappas, float).tolist(),
                         np.asarray(plan.palm_poses, float).tolist(), float(x), float(y), float(r))

    @property
    def alive(self) -> bool:
        return self._proc.is_alive()

    def close(self, timeout: float = 5.0) -> None:
        """Stop the loop and the child process."""
        if self._proc.is_alive():
            self._commands.put(None)
            self._proc.join(timeout)
        if self._proc.is_alive():
            self._proc.terminate()
