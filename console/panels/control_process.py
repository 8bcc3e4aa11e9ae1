"""The soft arm's 100 Hz loop in its own process, so the console's threads cannot delay it.

In the console process the render thread, viser's event loop and the panels hold the GIL for
milliseconds at a time (mesh updates, plot serialisation): a 100 Hz loop *thread* there misses
deadlines (measured: hundreds of overruns per minute, p99 period error tens of ms on 2 cores).
:class:`ControlProcess` therefore runs the simulated arm, the control stack and the real-time
:class:`hw_bridge.loop.LoopRunner` thread in a spawned child process (planning in a further
:class:`hw_bridge.loop.ProcessPlanner` process). The loop drives either the in-process sim
(``device="sim"``) or hardware through the serial stack (:mod:`hw_bridge.soft_arm_link`): the
device emulator on a pty with its UDP mocap and scene channel (``"emulator"``), MockHardware
with the same plant (``"mock"``), or a real controller (``port_path``). The console talks to it
with small messages:

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
import gc
import itertools
import multiprocessing
import queue
import threading
from typing import Any, Literal

import numpy as np

from console.panels.control_worlds import DISCONNECTED, NO_SERIAL_LINK  # noqa: F401 (re-export)
from console.panels.control_worlds import HardwareWorld as _HardwareWorld
from console.panels.control_worlds import SimWorld as _SimWorld
from hw_bridge.cpu_partition import CpuPartition, format_cpus, pin_process
from hw_bridge.loop import LoopSnapshot, LoopStats, SlowTick
from hw_bridge.parent_watch import exit_reason, run_reporting


@dataclasses.dataclass(frozen=True)
class ControlView:
    """What the console draws: loop snapshot, stats and the simulated scene.

    ``device`` says what the loop drives; with hardware, ``link`` is the link health and
    ``fault`` the hardware fault that stopped commanding (cleared by the operator's Arm).
    """

    snapshot: LoopSnapshot
    stats: LoopStats
    scheduling: str
    object_xy: tuple[float, float] | None
    object_radius: float | None
    captured: bool
    finger: np.ndarray | None  # (M, 2) gripper centreline in the world while closing
    device: str = "sim"
    link: Any = None  # hw_bridge.interface.LinkHealth with hardware
    fault: str | None = None
    slow_ticks: tuple[SlowTick, ...] = ()  # the loop's latest late / long ticks


@dataclasses.dataclass(frozen=True)
class DeviceOptions:
    """Which device the child's loop drives (see :class:`ControlProcess`)."""

    kind: str = "sim"
    port_path: str | None = None
    emulator_args: tuple[str, ...] = ()
    cpus: CpuPartition | None = None  # the loop (and emulator) on .realtime, planner on .other


def _child(robot_source: str, seed: int, commands: Any, replies: Any, publish_hz: float,
           stats_ticks: int, sched_priority: int | None, opts: DeviceOptions = DeviceOptions()) -> None:
    from hw_bridge.parent_watch import watch_parent
    watch_parent()  # the console died (any signal): SIGKILL this one, its children follow
    if opts.cpus is not None:  # start-up work (this and the children's imports) off the
        pin_process(opts.cpus.other)  # real-time CPU; the loop moves there once all started
        opts = dataclasses.replace(opts, emulator_args=(
            *opts.emulator_args, "--cpus", format_cpus(opts.cpus.realtime)))
    from core.control.stack import ControlStack
    from core.robots import load
    from hw_bridge.loop import LoopRunner, ProcessPlanner
    from hw_bridge.realtime import helper_priority as realtime_helper_priority
    from hw_bridge.realtime import promote_threads, shorten_gil_wait

    robot = load(robot_source)
    # Every thread of this process runs SCHED_FIFO just below the loop, so a thread that holds
    # the GIL is never preempted by ordinary processes while the loop waits for it
    # (hw_bridge.realtime); from the start, so the link's receive thread is real-time before
    # the first STATE is due. Processes started later (planner, emulator) do not inherit it.
    helper_priority = realtime_helper_priority(sched_priority)
    if helper_priority:
        shorten_gil_wait()
        promote_threads(helper_priority)
    try:
        world: Any = _SimWorld(robot, seed) if opts.kind == "sim" else _HardwareWorld(robot, seed, opts)
    except Exception as exc:  # noqa: BLE001 - reported to the parent, which shows it
        replies.put(("failed", f"{opts.kind} device: {exc}"))
        return
    world.configure()
    if helper_priority:
        promote_threads(helper_priority)  # the receive thread configure() started
    planner = ProcessPlanner(robot_source, cpus=None if opts.cpus is None else opts.cpus.other)
    stack = ControlStack(robot, 0.01, planner)
    runner = LoopRunner(world.device, stack, 0.01)

    def place(x: float, y: float, r: float) -> None:
        if world.kind == "sim":
            world.sim.place_object(x, y, r)

    def arm(s: ControlStack) -> None:
        world.arm(s)
        runner.fault = None

    def connect(s: ControlStack, port: str, baud: int) -> None:
        world.connect(s, port, baud)
        runner.fault = None  # a fresh link: the old fault is history (nothing is armed)

    def grasp_at(s: ControlStack, t: float, x: float, y: float, r: float) -> None:
        place(x, y, r)
        if not s.armed:
            arm(s)
        s.start(t)

    def execute(s: ControlStack, t: float, kappas: list, palms: list, x: float, y: float,
                r: float) -> None:
        from core.control.grasp_place import WaypointPlan
        place(x, y, r)
        if not s.armed:
            arm(s)
        s.execute(WaypointPlan(np.asarray(kappas, float), np.asarray(palms, float)), (x, y), t)

    actions = {
        "execute": execute,
        "arm": lambda s, t: arm(s),
        "disarm": lambda s, t: world.disarm(s),
        "goto": lambda s, t, q: s.goto(np.asarray(q, float), t),
        "stop": lambda s, t, reason: s.stop(t, reason),
        "start": lambda s, t: s.start(t),
        "place_object": lambda s, t, x, y, r: place(x, y, r),
        "grasp_at": grasp_at,
        "connect": lambda s, t, port, baud: connect(s, port, baud),
        "disconnect": lambda s, t: world.disconnect(s),
    }
    # With hardware the simulated object lives in the emulator / mock plant: placed from this
    # (command) thread before the loop's part runs, so the loop never waits on the scene channel.
    scene_first = {"place_object", "grasp_at", "execute"} if world.kind != "sim" else set()
    stop = threading.Event()
    on_cpus = "" if opts.cpus is None else f" on CPU {format_cpus(opts.cpus.realtime)}"

    def scheduling() -> str:  # what the loop thread got, and where it runs
        return runner.scheduling + on_cpus

    def publish() -> None:
        n = 0
        while not stop.wait(1.0 / publish_hz):
            obj_xy, radius, captured, finger, link, fault = world.scene(runner)
            fault = fault or runner.fault
            view = ControlView(runner.snapshot, runner.stats(last=stats_ticks), scheduling(),
                               obj_xy, radius, captured, finger, world.kind, link, fault,
                               tuple(runner.slow_ticks))
            replies.put(("view", view))
            n += 1
            if helper_priority and n % int(publish_hz) == 1:  # queue feeders start lazily
                promote_threads(helper_priority)

    # Everything built so far lives as long as the process: out of the collector's sight, so a
    # full collection triggered in the loop thread scans only what the loop allocates.
    gc.collect()
    gc.freeze()
    try:
        planner.warm.result(60)  # the worker's start-up done, on the other CPUs
    except Exception:  # noqa: BLE001 - a broken worker is replaced at the first plan
        pass
    if opts.cpus is not None:
        pin_process(opts.cpus.realtime)  # every thread; those started later inherit it
    runner.start(sched_priority=sched_priority)
    pub = threading.Thread(target=publish, name="control-publish", daemon=True)
    pub.start()
    if helper_priority:
        promote_threads(helper_priority)
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
            if name in scene_first:
                x, y, r = args[-3:]
                try:
                    world.place_object(x, y, r)
                except (RuntimeError, OSError, ValueError) as exc:
                    replies.put(("reply", cid, str(exc)))
                    continue
                if name == "place_object":
                    replies.put(("reply", cid, None))
                    continue
            fut = runner.submit(lambda s, t, fn=fn, args=args: fn(s, t, *args))
            fut.add_done_callback(lambda f, cid=cid: replies.put(
                ("reply", cid, None if f.exception() is None else str(f.exception()))))
    finally:
        stop.set()
        runner.stop()
        pub.join(2.0)
        world.close()
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
        device: What the loop drives: ``"sim"`` (SoftArmSim in the loop, the default),
            ``"emulator"`` (the child spawns ``python -m hw_bridge.emulator`` on a pty and
            talks DEMAND/STATE to it; arm shape from its UDP mocap stream), ``"mock"``
            (MockHardware with the same sim in-process). Giving ``port_path`` selects a real
            controller on that serial device (mocap on the robot's ``[emulator].mocap_port``).
        port_path: Serial device of a real controller (no emulator is spawned).
        emulator_args: Extra emulator arguments (fault injection: ``("--drop", "0.01")``).
        cpus: Where the processes run (:mod:`hw_bridge.cpu_partition`): ``"auto"`` (the
            default) the loop and its emulator on the highest CPU, the planner on the others;
            None: anywhere.

    With hardware, Arm (and grasp_at/execute while disarmed) configures and activates the
    link in the loop thread; a link fault stops commanding and shows in ``view.fault``, and
    nothing re-arms until the operator arms again. :meth:`disconnect_link` /
    :meth:`connect_link` close and re-open the link (a new SerialHardware on the given port,
    configured but not armed); after a Disconnect, Arm is refused until Connect, and the loop
    keeps reading motion capture only. :attr:`bridge_controls` offers all this to the Hardware
    panel as a :class:`hw_bridge.controls.BridgeControls`.
    """

    def __init__(self, robot: Any, seed: int = 0, publish_hz: float = 30.0,
                 stats_ticks: int = 1000, sched_priority: int | None = 50,
                 device: Literal["sim", "emulator", "mock"] = "sim",
                 port_path: str | None = None, emulator_args: tuple[str, ...] = (),
                 cpus: CpuPartition | None | Literal["auto"] = "auto"):
        if device not in ("sim", "emulator", "mock"):
            raise ValueError(f"device must be 'sim', 'emulator' or 'mock', got {device!r}")
        if cpus == "auto":
            cpus = CpuPartition.default()
        opts = DeviceOptions("port" if port_path else device, port_path, tuple(emulator_args),
                             cpus)
        self.device = opts.kind
        self.failure: str | None = None
        ctx = multiprocessing.get_context("spawn")
        self.robot = robot
        self._commands = ctx.Queue()
        self._replies = ctx.Queue()
        # Not a daemon: it starts its own planner process. close() (also at exit) ends it.
        self._proc = ctx.Process(target=run_reporting, name="soft-arm-control",  # (a failure's
                                 args=(_child, self._replies,  # reason -> self.failure)
                                       str(robot.source), seed, self._commands, self._replies,
                                       publish_hz, stats_ticks, sched_priority, opts))
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
                if not self._proc.is_alive():  # killed or crashed: the panel says so
                    self.failure = self.failure or exit_reason(self._proc.exitcode)
                    return
                continue
            except (EOFError, OSError):
                return
            if msg[0] == "view":
                self.view = msg[1]
            elif msg[0] == "failed":
                self.failure = msg[1]
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

    def connect_link(self, port: str, baud: int = 0) -> cf.Future:
        """Close the link and open ``port`` at ``baud`` (0: the robot file's); inactive."""
        return self.send("connect", str(port), int(baud))

    def disconnect_link(self) -> cf.Future:
        """Stop commanding, DISARM and close the port; Arm refuses until :meth:`connect_link`."""
        return self.send("disconnect")

    @property
    def bridge_controls(self) -> ProcessBridgeControls:
        """This loop as a :class:`hw_bridge.controls.BridgeControls` (the Hardware panel's)."""
        return ProcessBridgeControls(self)

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


class ProcessBridgeControls:
    """:class:`hw_bridge.controls.BridgeControls` over a :class:`ControlProcess`.

    Every method only queues a command for the child's loop thread (the only writer to the
    hardware) and returns at once; refusals land in ``health().fault`` (and in the link's
    fault shown by the Control panel). Arm / Disarm are the Control panel's: the link is
    activated (ARM) *and* the control stack starts commanding (holding where the arm is),
    since an armed device without demands trips its watchdog within ``watchdog_ms``.
    On the simulated arm Connect / Disconnect do nothing and health() then says so.
    """

    def __init__(self, ctl: ControlProcess):
        self.ctl = ctl

    def connect(self, port: str, baud: int) -> None:
        self.ctl.connect_link(port, baud)

    def disconnect(self) -> None:
        self.ctl.disconnect_link()

    def arm(self) -> None:
        self.ctl.arm()

    def disarm(self) -> None:
        self.ctl.disarm()

    def health(self) -> Any:
        """The newest published :class:`~hw_bridge.interface.LinkHealth` (None: no link yet)."""
        view = self.ctl.view
        return None if view is None else view.link
