"""The extensible arm's 100 Hz runner in its own real-time process, like the soft arm's loop.

Measured on the lab's 2-core machine with other work on both cores: the runner as a
``SCHED_FIFO`` *thread* of the console process (GIL switch interval 0.5 ms) lost its serial
link within 40 s in 3 of 3 runs while following the demo motion (period error max 35-414 ms,
"no valid STATE for 42-432 ms"): a console thread holding the GIL is descheduled by ordinary
processes while the loop waits for it. In its own process every thread is real-time just below
the loop and pinned to the real-time CPU (:mod:`hw_bridge.loop_process`).

:class:`ExtensibleProcess` offers the console the runner's interface (``start`` / ``connect`` /
``execute`` / ``move_to`` / ``stop`` / ``setpoint`` / ``wait`` / ``snapshot`` / ``port`` /
``bridge_controls``);
in the child an :class:`~hw_bridge.extensible_runner.ExtensibleRunner` runs every command
(:mod:`hw_bridge.commands`). The console's command reaches it as
:class:`~hw_bridge.commands.Setpoint` messages (:meth:`ExtensibleProcess.setpoint`, called by the
console core for each new command that is not the runner's own), and the measured posture, settled commands and job
results come back to the store and to :meth:`ExtensibleProcess.wait`.
"""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import gc
import itertools
import threading
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from core.planning.paths import MotionPath
from core.robots import ExtensibleArm
from hw_bridge.commands import ConnectFactory, Hold, RunPath, Setpoint
from hw_bridge.cpu_partition import CpuPartition, format_cpus, pin_process
from hw_bridge.extensible_jobs import JobResult, RunnerSnapshot
from hw_bridge.extensible_runner import check_path, move_path
from hw_bridge.loop import LoopStats, SlowTick
from hw_bridge.loop_process import (LoopProcess, ProcessBridgeControls, reply_when_done,
                                    serve_commands)

SOURCE = "runner"  # the store's source of the runner's own commands and reports


@dataclasses.dataclass(frozen=True)
class ExtensibleView:
    """What the child publishes: the runner's snapshot, the link health and port, and the
    loop's timing (over its latest 1000 ticks, refreshed once a second; the slow ones)."""

    snapshot: RunnerSnapshot
    link: Any  # hw_bridge.interface.LinkHealth (None before the first connect)
    port: str
    scheduling: str
    stats: LoopStats
    slow_ticks: tuple[SlowTick, ...] = ()


@dataclasses.dataclass(frozen=True)
class ExtensibleOptions:
    """Which hardware the child's runner drives and how (see :class:`ExtensibleProcess`)."""

    kind: Literal["mock", "port"]
    port_path: str | None = None
    always_report: bool = False
    publish_hz: float = 30.0
    sched_priority: int | None = 50
    cpus: CpuPartition | None = None


class PipeLink:
    """Child side of the console's :class:`~hw_bridge.extensible_jobs.PoseLink`: the newest
    :class:`Setpoint` from the parent; measured postures go back with the published view,
    settled commands at once."""

    def __init__(self, replies: Any, always_report: bool) -> None:
        self.replies = replies
        self.always_report = always_report
        self.latest: tuple[int, Any] | None = None
        self.measured_delta: Any = None
        self.measured_n = 0

    def setpoint(self) -> tuple[int, Any] | None:
        return self.latest

    def measured(self, delta: Any) -> None:
        self.measured_delta, self.measured_n = delta, self.measured_n + 1

    def settled(self, delta: Any) -> int:
        seen = -1 if self.latest is None else self.latest[0]  # (SOURCE's own: not sent back)
        self.replies.put(("settled", np.asarray(delta, float), seen))
        return seen


def _hardware(robot: ExtensibleArm, opts: ExtensibleOptions) -> Any:
    from hw_bridge.extensible_runner import mock_factory
    if opts.kind == "mock":
        return mock_factory(robot)
    from hw_bridge.config import BridgeConfig
    from hw_bridge.interface import SerialHardware
    hardware = SerialHardware(BridgeConfig.from_robot(robot), str(opts.port_path))
    return lambda: hardware


def _child(robot_source: str, opts: ExtensibleOptions, commands: Any, replies: Any) -> None:
    from hw_bridge.parent_watch import watch_parent
    watch_parent()  # the console died (any signal): SIGKILL this one, its children follow
    if opts.cpus is not None:  # start-up off the real-time CPU; the loop moves there later
        pin_process(opts.cpus.other)
    from core.labdata.ticks import TickRing, layout_for
    from core.robots import load
    from hw_bridge.extensible_runner import ExtensibleRunner
    from hw_bridge.realtime import helper_priority as realtime_helper_priority
    from hw_bridge.realtime import promote_new_threads, promote_threads, shorten_gil_wait

    robot = load(robot_source)
    helper_priority = realtime_helper_priority(opts.sched_priority)
    if helper_priority:
        shorten_gil_wait()
        promote_threads(helper_priority)
    try:
        factory = _hardware(robot, opts)  # type: ignore[arg-type]
        link = PipeLink(replies, opts.always_report)
        runner = ExtensibleRunner(robot, factory, link=link, on_new_link=promote_new_threads)
    except Exception as exc:  # noqa: BLE001 - reported to the parent, which shows it
        replies.put(("failed", f"{opts.kind} device: {exc}"))
        return

    def on_result(result: JobResult) -> None:
        runner._on_result(result)
        replies.put(("result", result))
    runner.streamer.on_result = on_result
    runner.loop.tick_ring = TickRing(layout_for(robot))  # every tick, sent with the views
    stop = threading.Event()
    on_cpus = "" if opts.cpus is None else f" on CPU {format_cpus(opts.cpus.realtime)}"

    def publish() -> None:
        sent, n = 0, 0
        loop = runner.loop
        stats = loop.stats(last=1000)
        while not stop.wait(1.0 / opts.publish_hz):
            if link.measured_n != sent:
                sent = link.measured_n
                replies.put(("measured", np.asarray(link.measured_delta, float)))
            if n % int(opts.publish_hz) == 0:  # once a second: percentiles hold the GIL ~1 ms
                stats = loop.stats(last=1000)
            replies.put(("view", ExtensibleView(runner.snapshot, runner.bridge_controls.health(),
                                                runner.port, loop.scheduling + on_cpus, stats,
                                                tuple(loop.slow_ticks))))
            ticks = loop.tick_ring.drain()
            if ticks is not None:
                replies.put(("ticks", ticks))
            n += 1
            if helper_priority and n % int(opts.publish_hz) == 1:  # queue feeders start lazily
                promote_threads(helper_priority)

    def handle(cid: int, cmd: Any) -> None:
        if isinstance(cmd, Setpoint):
            link.latest = (cmd.seq, np.asarray(cmd.delta, float))
            return
        reply_when_done(replies, cid, runner.send(cmd), with_result=isinstance(cmd, ConnectFactory))

    gc.collect()
    gc.freeze()  # what lives as long as the process: out of the loop's collections
    if opts.cpus is not None:
        pin_process(opts.cpus.realtime)
    runner.loop.start(sched_priority=opts.sched_priority)
    pub = threading.Thread(target=publish, name="extensible-publish", daemon=True)
    pub.start()
    if helper_priority:
        promote_threads(helper_priority)
    try:
        serve_commands(commands, handle)
    finally:
        stop.set()
        pub.join(2.0)
        runner.close()


class ExtensibleProcess(LoopProcess):
    """The extensible arm's runner in a child process, with the runner's interface.

    Args:
        robot: The extensible arm (its ``source`` file is loaded in the child).
        store: The console's :class:`console.core.state.StateStore`: its commands are followed while
            armed and idle (from the first one after Arm), the measured posture is reported there
            (always when the store does not mirror commands, else while a job runs).
        kind: ``"mock"`` (an in-process MockHardware in the child) or ``"port"`` (a
            SerialHardware on ``port_path``: a controller or the device emulator's pty).
        cpus: Where the processes run (:mod:`hw_bridge.cpu_partition`): ``"auto"`` the loop on
            the highest CPU, the rest on the others; None: anywhere.

    Not started: :meth:`start` spawns the child and connects, disarmed (only the operator's Arm,
    :attr:`bridge_controls`, arms; it holds where the encoders are). :meth:`restart` replaces a
    dead or silent child by a new one, which connects again, disarmed.
    """

    def __init__(self, robot: ExtensibleArm, store: Any, kind: Literal["mock", "port"] = "mock",
                 port_path: str | None = None, *,
                 cpus: CpuPartition | None | Literal["auto"] = "auto",
                 sched_priority: int | None = 50, publish_hz: float = 30.0) -> None:
        from hw_bridge.config import BridgeConfig
        if kind not in ("mock", "port") or (kind == "port" and not port_path):
            raise ValueError(f"kind must be 'mock' or 'port' with a port_path, got {kind!r}")
        super().__init__("extensible-control")
        if cpus == "auto":
            cpus = CpuPartition.default()
        always_report = not getattr(store, "mirror_commands", True)
        self.robot = robot
        self.store = store
        self.period_s = BridgeConfig.from_robot(robot).period_s
        self.options = ExtensibleOptions(kind, port_path, always_report, publish_hz,
                                         sched_priority, cpus)
        self.view: ExtensibleView | None = None
        self.connecting: cf.Future | None = None
        self._job_ids = itertools.count(1)
        self._results: dict[int, JobResult] = {}
        self._done = threading.Condition()
        self._start_lock = threading.Lock()
        self._sent_seq = -1  # the newest set-point sent to the child (see on_message)
        self._sent_lock = threading.Lock()

    # -- lifecycle -------------------------------------------------------------------------
    @property
    def started(self) -> bool:
        return self.alive

    def start(self, sched_priority: int | None = None) -> ExtensibleProcess:
        """Spawn the child (its loop starts at once) and connect (idempotent; returns at once)."""
        with self._start_lock:
            if self._proc is None:
                self.spawn(_child, (str(self.robot.source), self.options, self._commands,
                                    self._replies))
                self.connecting = self.connect()
        return self

    def use_port(self, port_path: str) -> None:
        """Where a restarted child connects (a revived device emulator's new pty); the running
        child is told by the operator's Connect."""
        if self.options.kind != "port":
            raise ValueError("only a 'port' runner has a port to change")
        self.options = dataclasses.replace(self.options, port_path=str(port_path))

    def restart(self, timeout: float = 5.0) -> None:
        """A new child in place of a dead or silent one (:meth:`LoopProcess.restart`); it
        connects again (:meth:`use_port`'s port), disarmed. Jobs the old child ran end (their
        :meth:`wait` times out)."""
        with self._start_lock:
            if self._proc is not None:  # the options as they are now (use_port)
                self._args = (str(self.robot.source), self.options, self._commands,
                              self._replies)
            with self._sent_lock:
                self._sent_seq = -1  # the new child has seen no set-point
            super().restart(timeout)
            self.connecting = self.connect()

    def connect(self) -> cf.Future:
        """(Re)configure the hardware, disarmed (only the operator's Arm arms)."""
        return self.send(ConnectFactory())

    def close(self, timeout: float = 5.0) -> None:
        """Disarm and release the hardware, stop the child."""
        super().close(timeout)

    @property
    def bridge_controls(self) -> ProcessBridgeControls:
        """This runner as a :class:`hw_bridge.controls.BridgeControls` (the Hardware panel's)."""
        return ProcessBridgeControls(self)

    # -- jobs ------------------------------------------------------------------------------
    def execute(self, path: MotionPath, label: str = "path") -> int:
        """Queue ``path``; returns its job id."""
        check_path(self.robot, path)
        job_id = next(self._job_ids)
        self.send(RunPath(job_id, label, path))
        return job_id

    def move_to(self, lengths: npt.ArrayLike, label: str = "move") -> int:
        """Queue a joint move to rack lengths (n, 3) (moved into the limits first)."""
        return self.execute(move_path(self.robot, lengths, self.period_s), label)

    def stop(self) -> cf.Future:
        """Hold position (aborts the running job)."""
        return self.send(Hold())

    def wait(self, job_id: int, timeout: float | None = None) -> JobResult | None:
        """Block until job ``job_id`` ended; None on timeout."""
        with self._done:
            self._done.wait_for(lambda: job_id in self._results, timeout)
            return self._results.get(job_id)

    @property
    def snapshot(self) -> RunnerSnapshot:
        """Newest published telemetry (any thread)."""
        view = self.view
        return RunnerSnapshot("disconnected") if view is None else view.snapshot

    @property
    def port(self) -> str:
        view = self.view
        return "" if view is None else view.port

    # -- messages from the child (reader thread) ------------------------------------------
    def on_message(self, msg: tuple[Any, ...]) -> None:
        kind, payload = msg[0], msg[1]
        if kind == "result":
            with self._done:
                self._results[payload.job_id] = payload
                self._done.notify_all()
        elif kind == "measured":
            self.store.report(payload, SOURCE)
        elif kind == "settled":
            # Where the runner holds, as the console's command: unless a newer set-point than
            # the newest it had seen was on its way (a jog started again after an expiry): the
            # runner follows that one, and the console's command must stay with it.
            with self._sent_lock:
                if self._sent_seq <= int(msg[2]):
                    self.store.request(payload, SOURCE)

    def setpoint(self, seq: int, delta: npt.ArrayLike) -> None:
        """Send the console's commanded posture ``delta`` (n, 3) with its store sequence number
        ``seq``; the runner follows the newest while armed and idle. The console core calls
        this for each new command that is not the runner's own (nothing here watches the
        store)."""
        rows = tuple(tuple(float(v) for v in row) for row in np.asarray(delta, float))
        if self.alive:
            with self._sent_lock:
                self._sent_seq = int(seq)
                self._commands.put((0, Setpoint(int(seq), rows)))
