"""The soft arm's 100 Hz loop in its own process, so the console's threads cannot delay it.

In the console process the render thread, viser's event loop and the panels hold the GIL for
milliseconds at a time (mesh updates, plot serialisation): a 100 Hz loop *thread* there misses
deadlines (measured: hundreds of overruns per minute, p99 period error tens of ms on 2 cores).
:class:`ControlProcess` therefore runs the simulated arm, the control stack and the real-time
:class:`hw_bridge.loop.LoopRunner` thread in a spawned child process (planning in a further
:class:`hw_bridge.planner_process.ProcessPlanner` process), through the
:class:`hw_bridge.loop_process.LoopProcess` wrapper the extensible arm's process shares. The loop
drives either the in-process sim (``device="sim"``) or hardware through the serial stack
(:mod:`hw_bridge.soft_arm_link`): the device emulator on a pty with its UDP mocap and scene
channel (``"emulator"``), MockHardware with the same plant (``"mock"``), or a real controller
(``port_path``). The console talks to it with small messages:

* commands go down a queue as the typed dataclasses of :mod:`hw_bridge.commands`
  (:class:`~hw_bridge.commands.Arm`, :class:`~hw_bridge.commands.Goto`,
  :class:`~hw_bridge.commands.GraspAt`, ...), are applied by the child's loop thread at its next
  tick (dispatched on their type; the link verbs by the world's
  :class:`~hw_bridge.link_supervisor.LinkSupervisor`), and each returns a Future that the reply
  resolves (with the loop's error, if it refused);
* :class:`~hw_bridge.commands.RunRow` takes a row of objects to a bin, one after another: the
  stack is a :class:`core.control.row_stack.RowControlStack`, which puts each object whose turn
  begins into the simulated world (sim: from the loop thread; hardware: handed to a placer
  thread, so the loop never waits on the emulator's scene channel), and STOP ends the row;
* the child publishes a :class:`ControlView` (the loop snapshot, recent stats, the true object,
  the gripper finger for drawing and the newest row's report) at ``publish_hz``;
  :attr:`ControlProcess.view` is the newest one (a reference swap, no lock for readers); with
  each view go the loop's ticks since the last one (a ``core.labdata.ticks.TickBatch``, every
  tick, for recordings: :attr:`LoopProcess.tick_listeners`).
"""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import gc
import queue
import threading
from typing import Any, Literal

import numpy as np

from hw_bridge.commands import (BRIDGE_COMMANDS, SCENE_COMMANDS, Arm, Connect, Disarm, Disconnect,
                               ExecutePlan, Goto, GraspAt, PlaceObject, RunRow, SoftArmCommand,
                               StartGrasp, StopArm, bin_rows, obstacle_rows,
                               obstacles_of)
from hw_bridge.cpu_partition import CpuPartition, format_cpus, pin_process
from hw_bridge.loop import LoopSnapshot, LoopStats, SlowTick
from hw_bridge.loop_process import (LoopProcess, ProcessBridgeControls, reply_when_done,
                                    serve_commands)
from hw_bridge.soft_arm_worlds import DeviceOptions, HardwareWorld, SimWorld


ARM_FIRST = "Arm first (press Arm): Execute does not arm the arm"
ROW_ARM_FIRST = "Arm first (press Arm): clearing the table does not arm the arm"
TASKS = (Goto, StartGrasp, GraspAt, ExecutePlan, RunRow)  # refused while a row runs


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
    row: Any = None  # core.control.row_stack.RowReport of the newest row (None before one)
    executing: Any = None  # core.control.run_estimate.ExecutingPlan the machine runs, or None


def _child(robot_source: str, seed: int, commands: Any, replies: Any, publish_hz: float,
           stats_ticks: int, sched_priority: int | None, opts: DeviceOptions = DeviceOptions()) -> None:
    from hw_bridge.parent_watch import watch_parent
    watch_parent()  # the console died (any signal): SIGKILL this one, its children follow
    if opts.cpus is not None:  # start-up work (this and the children's imports) off the
        pin_process(opts.cpus.other)  # real-time CPU; the loop moves there once all started
        opts = dataclasses.replace(opts, emulator_args=(
            *opts.emulator_args, "--cpus", format_cpus(opts.cpus.realtime)))
    from core.control.row_stack import RowControlStack
    from core.labdata.ticks import TickRing, layout_for
    from core.robots import load
    from hw_bridge.loop import LoopRunner
    from hw_bridge.planner_process import ProcessPlanner
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
        world: Any = SimWorld(robot, seed) if opts.kind == "sim" else HardwareWorld(robot, seed, opts)
    except Exception as exc:  # noqa: BLE001 - reported to the parent, which shows it
        replies.put(("failed", f"{opts.kind} device: {exc}"))
        return
    world.configure()
    if helper_priority:
        promote_threads(helper_priority)  # the receive thread configure() started
    planner = ProcessPlanner(robot_source, cpus=None if opts.cpus is None else opts.cpus.other)
    stack = RowControlStack(robot, 0.01, planner)
    runner = LoopRunner(world.device, stack, 0.01)
    runner.tick_ring = TickRing(layout_for(robot))  # every tick, sent with the views

    def place(x: float, y: float, r: float) -> None:
        if world.kind == "sim":
            world.sim.place_object(x, y, r)

    # A row's later objects: the sim's are placed by the loop thread itself; with hardware a
    # placer thread talks to the emulator / mock plant (the loop only queues them).
    to_place: queue.SimpleQueue = queue.SimpleQueue()

    def place_row_object(obj: Any) -> None:
        if world.kind == "sim":
            world.sim.place_object(obj.x, obj.y, obj.r)
        else:
            to_place.put(obj)

    def placer() -> None:
        while (obj := to_place.get()) is not None:
            try:
                world.place_object(obj.x, obj.y, obj.r)
            except (RuntimeError, OSError, ValueError):
                pass  # the machine does not see it: that object fails with its reason

    def bin_of(cmd: RunRow | GraspAt | ExecutePlan, required: bool = False) -> Any:
        """The command's table bin as ``BinParams`` (None: it names none, unless
        ``required``); ValueError when its poses are not n curvatures within the limits."""
        from core.control.params import BinParams
        kappas = [np.asarray(k, float) for k in (cmd.bin_kappa, cmd.bin_kappa_right) if k]
        if not kappas and not required:
            return None
        if not kappas or any(k.shape != (robot.n_segments,)
                             or not np.all(np.abs(k) <= robot.kappa_max) for k in kappas):
            raise ValueError(f"the bin needs {robot.n_segments} curvatures within "
                             f"±{robot.kappa_max:g} 1/m")
        return BinParams(kappas[0], robot.bin.drop_radius_m,
                         kappas[1] if len(kappas) > 1 else None)

    def run_row(s: RowControlStack, t: float, cmd: RunRow) -> None:
        from core.control.row import RowObject
        if not s.armed:
            raise RuntimeError(ROW_ARM_FIRST)
        objects = [RowObject(*o) for o in cmd.objects]  # ValueError names a bad one
        if not objects:
            raise ValueError("no objects to take to the bin")
        bin_params = bin_of(cmd, required=True)
        s.set_obstacles(obstacles_of(cmd), cmd.clearance)  # ValueError: nothing set, nothing runs
        place(objects[0].x, objects[0].y, objects[0].r)
        s.start_row(cmd.row_id, objects, bin_params, t, place_row_object)

    def link(s: RowControlStack, cmd: Any) -> None:
        world.apply(cmd, s)
        if isinstance(cmd, (Arm, Connect)):
            runner.fault = None  # armed, or a fresh link: the old fault is history

    def apply(s: RowControlStack, t: float, cmd: SoftArmCommand) -> None:
        """Loop thread: one command, dispatched on its type."""
        if isinstance(cmd, TASKS):
            s.require_no_row()  # STOP first: nothing else takes over the arm mid-row
        if isinstance(cmd, BRIDGE_COMMANDS):
            link(s, cmd)
        elif isinstance(cmd, Goto):
            s.goto(np.asarray(cmd.q, float), t)
        elif isinstance(cmd, StopArm):
            s.stop(t, cmd.reason)
        elif isinstance(cmd, StartGrasp):
            s.start(t)
        elif isinstance(cmd, PlaceObject):
            place(cmd.x, cmd.y, cmd.r)
        elif isinstance(cmd, RunRow):
            run_row(s, t, cmd)
        elif isinstance(cmd, (GraspAt, ExecutePlan)):
            if not s.armed:  # arming is the operator's own, visible act: never implied here
                raise RuntimeError(ARM_FIRST)
            bin_params = bin_of(cmd)  # ValueError before anything is set
            s.set_obstacles(obstacles_of(cmd), cmd.clearance)  # first plan and re-plans
            s.set_bin(bin_params)  # the table's bin, else the robot file's
            place(cmd.x, cmd.y, cmd.r)
            if isinstance(cmd, GraspAt):
                s.start(t)
            else:
                from core.control.grasp_place import WaypointPlan
                s.execute(WaypointPlan(np.asarray(cmd.kappas, float),
                                       np.asarray(cmd.palms, float)), (cmd.x, cmd.y), t)
        else:
            raise TypeError(f"not a soft-arm command: {cmd!r}")

    # With hardware the simulated object lives in the emulator / mock plant: placed from this
    # (command) thread before the loop's part runs, so the loop never waits on the scene channel.
    scene_first = SCENE_COMMANDS if world.kind != "sim" else ()
    stop = threading.Event()
    on_cpus = "" if opts.cpus is None else f" on CPU {format_cpus(opts.cpus.realtime)}"

    def scheduling() -> str:  # what the loop thread got, and where it runs
        return runner.scheduling + on_cpus

    from core.control.run_estimate import executing_plan
    shown_plan: list[Any] = [None, None]  # (what it was built from, the ExecutingPlan)

    def executing() -> Any:
        """The plan the machine executes, built again only when it changed (a reference
        read of the loop thread's machine: plan, carry and re-plans are replaced, never
        edited in place)."""
        m = stack.machine
        key = (m.plan, m.plan_center is None, m.carry, m.replans, m.bin)
        if shown_plan[0] is None or any(a is not b for a, b in zip(key, shown_plan[0])):
            try:
                shown_plan[:] = [key, executing_plan(m)]
            except (AttributeError, TypeError, ValueError):  # mid-change: the next publish
                return shown_plan[1]
        return shown_plan[1]

    def publish() -> None:
        n = 0
        while not stop.wait(1.0 / publish_hz):
            obj_xy, radius, captured, finger, link, fault = world.scene(runner)
            fault = fault or runner.fault
            view = ControlView(runner.snapshot, runner.stats(last=stats_ticks), scheduling(),
                               obj_xy, radius, captured, finger, world.kind, link, fault,
                               tuple(runner.slow_ticks), stack.row_report(), executing())
            replies.put(("view", view))
            ticks = runner.tick_ring.drain()
            if ticks is not None:
                replies.put(("ticks", ticks))
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
    if world.kind != "sim":
        threading.Thread(target=placer, name="row-placer", daemon=True).start()
    if helper_priority:
        promote_threads(helper_priority)
    try:
        def handle(cid: int, cmd: Any) -> None:
            if isinstance(cmd, Connect) and world.kind == "emulator":
                try:  # a dead emulator is replaced here, off the loop thread (seconds)
                    cmd = world.revive_emulator(cmd)
                except (RuntimeError, OSError, ValueError, TimeoutError) as exc:
                    replies.put(("reply", cid, f"the device emulator did not start: {exc}"))
                    return
            if isinstance(cmd, RunRow) and world.kind != "sim":
                if not stack.armed:  # (the loop checks again) no object placed when refused
                    replies.put(("reply", cid, ROW_ARM_FIRST))
                    return
                if cmd.objects and not stack.row_running:  # the first object, before the row
                    try:
                        world.place_object(*cmd.objects[0])
                    except (RuntimeError, OSError, ValueError) as exc:
                        replies.put(("reply", cid, str(exc)))
                        return
            if isinstance(cmd, scene_first):
                try:
                    world.place_object(cmd.x, cmd.y, cmd.r)
                except (RuntimeError, OSError, ValueError) as exc:
                    replies.put(("reply", cid, str(exc)))
                    return
                if isinstance(cmd, PlaceObject):
                    replies.put(("reply", cid, None))
                    return
            reply_when_done(replies, cid, runner.submit(lambda s, t: apply(s, t, cmd)))

        serve_commands(commands, handle)  # until None or the console went away
    finally:
        stop.set()
        to_place.put(None)
        runner.stop()
        pub.join(2.0)
        world.close()
        planner.close()
        del runner, stack  # free ruckig objects before interpreter teardown
        gc.unfreeze()  # (what gc.freeze() kept, cycles among it included, is freed now: a
        gc.collect()   # ruckig object left for the teardown makes nanobind report a leak)


class ControlProcess(LoopProcess):
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

    Only Arm arms: grasp_at / execute while disarmed are refused with :data:`ARM_FIRST`
    (issue 19.3: Execute used to arm silently). With hardware, Arm configures and activates the
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
        super().__init__("soft-arm-control")
        self.device = opts.kind
        self.robot = robot
        self.view: ControlView | None = None
        self.spawn(_child, (str(robot.source), seed, self._commands, self._replies, publish_hz,
                            stats_ticks, sched_priority, opts))

    def send(self, cmd: SoftArmCommand) -> cf.Future:
        """Queue a command for the loop; the Future resolves when the loop applied it."""
        return super().send(cmd)

    def arm(self) -> cf.Future:
        return self.send(Arm())

    def disarm(self) -> cf.Future:
        return self.send(Disarm())

    def goto(self, q: Any) -> cf.Future:
        return self.send(Goto(tuple(float(v) for v in np.asarray(q).ravel())))

    def stop_arm(self, reason: str = "operator STOP") -> cf.Future:
        return self.send(StopArm(reason))

    def place_object(self, x: float, y: float, r: float) -> cf.Future:
        return self.send(PlaceObject(float(x), float(y), float(r)))

    def grasp_at(self, x: float, y: float, r: float, obstacles: Any = (),
                 clearance: float = 0.0, bin_params: Any = None) -> cf.Future:
        """Place the object and run the grasp task; every plan keeps ``clearance`` (m) from
        ``obstacles`` (``core.planning.obstacles.Obstacle``); the object goes to
        ``bin_params`` (the table's bin, ``core.control.row.bin_at``; None: the robot's)."""
        return self.send(GraspAt(float(x), float(y), float(r), obstacle_rows(obstacles),
                                 float(clearance), *bin_rows(bin_params)))

    def execute(self, plan: Any, x: float, y: float, r: float,
                bin_params: Any = None) -> cf.Future:
        """Place the object at (x, y) and run ``plan`` (a GraspPlan for it), then place it in
        ``bin_params`` (as :meth:`grasp_at`); re-plans keep the plan's clearance from the
        plan's obstacles."""
        rows = lambda a: tuple(tuple(float(v) for v in row) for row in np.asarray(a, float))  # noqa: E731
        return self.send(ExecutePlan(rows(plan.kappas), rows(plan.palm_poses), float(x),
                                     float(y), float(r),
                                     obstacle_rows(getattr(plan, "obstacles", ())),
                                     float(getattr(plan, "obstacle_margin", 0.0) or 0.0),
                                     *bin_rows(bin_params)))

    def run_row(self, row_id: int, objects: Any, bin_xy: Any, bin_kappa: Any,
                bin_kappa_right: Any = (), obstacles: Any = (),
                clearance: float = 0.0) -> cf.Future:
        """Take ``objects`` ((x, y, r) each, m) to the bin at ``bin_xy`` (``bin_kappa``: the
        configuration over it, ``bin_kappa_right`` the right finger's, :func:`core.control.row.bin_at`)
        one after another, every plan ``clearance`` (m) from ``obstacles``; armed only.
        Its progress and outcomes are ``view.row`` (a :class:`core.control.row_stack.RowReport`
        with this ``row_id``)."""
        flat = lambda k: tuple(float(v) for v in np.asarray(k, float).ravel())
        return self.send(RunRow(int(row_id), tuple(tuple(float(v) for v in o) for o in objects),
                                (float(bin_xy[0]), float(bin_xy[1])), flat(bin_kappa),
                                flat(bin_kappa_right), obstacle_rows(obstacles),
                                float(clearance)))

    def connect_link(self, port: str, baud: int = 0) -> cf.Future:
        """Close the link and open ``port`` at ``baud`` (0: the robot file's); inactive."""
        return self.send(Connect(str(port), int(baud)))

    def disconnect_link(self) -> cf.Future:
        """Stop commanding, DISARM and close the port; Arm refuses until :meth:`connect_link`."""
        return self.send(Disconnect())

    @property
    def bridge_controls(self) -> ProcessBridgeControls:
        """This loop as a :class:`hw_bridge.controls.BridgeControls` (the Hardware panel's)."""
        return ProcessBridgeControls(self)
