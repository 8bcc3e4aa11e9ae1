"""Runs the extensible arm's motion paths on the motors at 100 Hz and reads the tip back.

:class:`ExtensibleRunner` drives one :class:`~hw_bridge.interface.HardwareInterface`
(:class:`~hw_bridge.interface.SerialHardware` to the Arduino Due or the pty emulator, or
:class:`~hw_bridge.mock.MockHardware`) through :class:`hw_bridge.loop.LoopRunner` (absolute
deadlines, overruns skipped): every tick reads the encoders, converts them to rack lengths
(L = U m), Delta (eq. 2) and the measured tip (forward kinematics), and writes one DEMAND.

* A job (:meth:`ExtensibleRunner.execute` a :class:`~core.planning.paths.MotionPath`, or
  :meth:`ExtensibleRunner.move_to` rack lengths) streams its motor counts one period of the
  path per tick (sample ``floor(ticks * period * rate_hz)``: a late tick delays the path and
  never skips a sample the device would have to chase across a corner), preceded by a joint move from wherever the motors are to the
  path's first sample; after the last sample the final demand is held until the encoders are
  within ``settle_counts`` (or ``settle_timeout`` passes).
* Idle, the runner holds its last demand, or follows the console's newest commanded posture
  (through a :class:`PoseLink`) with rack, motor and tip speeds within the robot's limits and
  the posture within its rack and bending limits.
* :meth:`ExtensibleRunner.stop` holds position where the motors are. A hardware ERROR
  (link lost, watchdog, e-stop, ...) aborts the job and stops commanding; the snapshot reports
  the fault until a reconnect (:meth:`ExtensibleRunner.connect` or the operator's Connect).
  Connecting never arms: only the operator's Arm (:attr:`ExtensibleRunner.bridge_controls`)
  does, and it holds where the encoders are. Nothing re-arms by itself.
* :attr:`ExtensibleRunner.snapshot` is an immutable :class:`RunnerSnapshot` replaced every tick
  (no lock for readers); the job's commanded and measured tips go into a :class:`JobTrace`.

The pieces live in :mod:`hw_bridge.extensible_jobs` (encoder maths, joint moves, records),
:mod:`hw_bridge.extensible_streamer` (per-tick logic) and :mod:`hw_bridge.extensible_link`
(the hardware link; its connect / arm / disarm are :class:`hw_bridge.link_supervisor.
LinkSupervisor`'s, shared with the soft arm). Everything queued for the loop is a typed command
(:mod:`hw_bridge.commands`: :class:`~hw_bridge.commands.RunPath`, :class:`~hw_bridge.commands.
Hold`, :class:`~hw_bridge.commands.ConnectFactory`, :class:`~hw_bridge.commands.CloseLink`, and
the bridge verbs) that the loop thread dispatches on its type.
"""

from __future__ import annotations

import dataclasses
import itertools
import threading
from concurrent.futures import Future
from typing import Callable

import numpy as np
import numpy.typing as npt

from core.kinematics import delta as dk
from core.planning.paths import MotionPath
from core.robots import ExtensibleArm
from hw_bridge.commands import (BRIDGE_COMMANDS, CloseLink, ConnectFactory, ExtensibleCommand,
                               Hold, RunPath)
from hw_bridge.controls import BridgeControls
from hw_bridge.extensible_jobs import JobResult, PoseLink, RunnerSnapshot, joint_move
from hw_bridge.extensible_link import HardwareLink
from hw_bridge.extensible_streamer import Streamer
from hw_bridge.interface import HardwareInterface
from hw_bridge.loop import LoopRunner
from hw_bridge.realtime import shorten_gil_wait


class ExtensibleRunner:
    """The extensible arm's control thread: jobs in, demands out, telemetry back.

    Args:
        robot: The extensible arm.
        hardware_factory: Returns the interface to configure and activate on every
            :meth:`connect` (it may return the same instance each time).
        link: Optional console link (:class:`StoreLink`).
        period_s: Control period (default: the robot's ``[bridge].rate_hz``).
        settle_counts: A job ends once every encoder is within this of its final demand.
        settle_timeout: ... or this long after the last sample (s), reported as not settled.
        on_new_link: Called on the loop thread after every configure of a link (its new receive
            thread): :func:`hw_bridge.realtime.promote_new_threads` in a real-time process.
    """

    def __init__(self, robot: ExtensibleArm, hardware_factory: Callable[[], HardwareInterface],
                 *, link: PoseLink | None = None, period_s: float | None = None,
                 settle_counts: int = 3, settle_timeout: float = 3.0,
                 on_new_link: Callable[[], None] = lambda: None) -> None:
        if getattr(robot, "kind", None) != "delta":
            raise ValueError(f"robot must be an extensible (delta) arm, got {type(robot).__name__}")
        from hw_bridge.config import BridgeConfig
        self.robot = robot
        self.period_s = period_s or BridgeConfig.from_robot(robot).period_s
        self.device = HardwareLink(robot, hardware_factory,
                                   health_every=max(1, round(0.1 / self.period_s)),
                                   on_new_link=on_new_link)
        self.streamer = Streamer(robot, self.period_s, link, settle_counts, settle_timeout)
        self.streamer.on_result = self._on_result
        self.device.streamer = self.streamer
        # Short spin: streaming position demands needs no sub-0.1 ms deadlines; saves CPU.
        self.loop = LoopRunner(self.device, self.streamer, self.period_s,  # type: ignore[arg-type]
                               spin_ns=100_000)
        self._ids = itertools.count(1)
        self._results: dict[int, JobResult] = {}
        self._done = threading.Condition()
        self._start_lock = threading.Lock()
        self.connecting: Future | None = None  # the first connect, queued by start()

    # -- lifecycle -------------------------------------------------------------------------
    @property
    def started(self) -> bool:
        return self.loop.running

    def start(self, sched_priority: int | None = 50) -> "ExtensibleRunner":
        """Start the 100 Hz thread and connect (idempotent; returns at once).

        The loop thread asks for ``SCHED_FIFO`` (``sched_priority``; refused without the
        permission) and the process's GIL switch interval drops to 0.5 ms: this loop shares the
        console's process, whose threads (viser, rendering) would otherwise hold the GIL for up
        to 5 ms at a time and, on a loaded machine, trip the 40 ms link timeout.
        """
        with self._start_lock:
            if not self.loop.running:
                if sched_priority:
                    shorten_gil_wait()
                self.loop.start(sched_priority=sched_priority)
                self.connecting = self.connect()
        return self

    @property
    def factory(self) -> Callable[[], HardwareInterface]:
        """Where :meth:`connect` gets its hardware (an operator's Connect replaces it)."""
        return self.device.factory

    @property
    def bridge_controls(self) -> BridgeControls:
        """This runner as a :class:`hw_bridge.controls.BridgeControls` (the Hardware panel's).

        The same object every time (a :class:`~hw_bridge.controls.QueuedBridgeControls`). Its
        ``connect(port, baud)``, ``disconnect()``, ``arm()`` and ``disarm()`` only enqueue and
        return at once; the runner's loop thread (the only one that touches the hardware)
        applies them at the start of its next tick (:class:`~hw_bridge.extensible_link.
        HardwareLink`): Connect opens a new SerialHardware on the port at the baud rate
        (configured, telemetry flowing, not armed; ``mock://`` for the in-process mock);
        Disconnect stops commanding and closes the port (Arm is refused until Connect); Arm
        activates and holds where the encoders are (the console's command is set there);
        Disarm stops commanding and DISARMs. A running job is aborted by every one of them.
        ``health()`` returns the newest :class:`~hw_bridge.interface.LinkHealth` (published
        about 10 times a second and after every command or fault; None before any link was
        opened); a fault (link lost, watchdog, e-stop, a refused command) shows in its
        ``fault``, and nothing re-arms until the operator arms again. Needs :meth:`start`.
        """
        return self.device.controls

    def connect(self) -> Future:
        """(Re)configure the hardware from the factory, on the loop thread, disarmed: nothing
        is commanded until the operator's Arm (:attr:`bridge_controls`), which holds where the
        encoders are."""
        return self.send(ConnectFactory())

    def send(self, cmd: ExtensibleCommand) -> Future:
        """Queue ``cmd`` for the loop thread; the Future resolves once it was applied."""
        return self.loop.submit(lambda stack, t: self._apply(cmd, t))

    def _apply(self, cmd: ExtensibleCommand, t: float) -> object:
        """Loop thread: run one command (dispatch on its type)."""
        if isinstance(cmd, RunPath):
            return self.streamer.start_job(cmd.job_id, cmd.label, cmd.path)
        if isinstance(cmd, Hold):
            return self.streamer.halt(t)
        if isinstance(cmd, ConnectFactory):
            return self.device.open_link()
        if isinstance(cmd, CloseLink):
            return self.device.close()
        if isinstance(cmd, BRIDGE_COMMANDS):
            self.device.apply(cmd)
            return self.device.publish()
        raise TypeError(f"not a command for the extensible arm: {cmd!r}")

    def close(self) -> None:
        """Disarm and release the hardware, stop the thread (and a MockHardware's device)."""
        if self.loop.running:
            try:  # the control thread is the one that talks to the hardware
                self.send(CloseLink()).result(2)
            except Exception:  # noqa: BLE001 - closing anyway
                pass
            self.loop.stop()
        hw = self.device.hw
        if hw is not None:
            hw.cleanup()
            if hasattr(hw, "shutdown"):
                hw.shutdown()

    # -- jobs ------------------------------------------------------------------------------
    def execute(self, path: MotionPath, label: str = "path") -> int:
        """Queue ``path`` (from :func:`core.planning.paths.plan_path`); returns its job id."""
        check_path(self.robot, path)
        job_id = next(self._ids)
        self.send(RunPath(job_id, label, path))
        return job_id

    def move_to(self, lengths: npt.ArrayLike, label: str = "move") -> int:
        """Queue a joint move from wherever the motors are to rack lengths (n, 3) (moved into
        the rack and bending limits first)."""
        return self.execute(move_path(self.robot, lengths, self.period_s), label)

    def stop(self) -> Future:
        """Hold position (aborts the running job)."""
        return self.send(Hold())

    def wait(self, job_id: int, timeout: float | None = None) -> JobResult | None:
        """Block until job ``job_id`` ended; None on timeout."""
        with self._done:
            self._done.wait_for(lambda: job_id in self._results, timeout)
            return self._results.get(job_id)

    def _on_result(self, result: JobResult) -> None:
        with self._done:
            self._results[result.job_id] = result
            self._done.notify_all()

    @property
    def port(self) -> str:
        """The link's port ("" before the first connect)."""
        return str(getattr(self.device.hw, "port", "") or "")

    @property
    def snapshot(self) -> RunnerSnapshot:
        """Newest telemetry (any thread)."""
        return self.streamer.snapshot


def check_path(robot: ExtensibleArm, path: MotionPath) -> None:
    """A job's path must carry motor counts for every motor (ValueError otherwise)."""
    if path.motor_counts.shape[1:] != (3 * robot.n_segments,) or len(path.times) < 1:
        raise ValueError(f"path must have motor counts of shape (K, {3 * robot.n_segments})")


def move_path(robot: ExtensibleArm, lengths: npt.ArrayLike, period_s: float) -> MotionPath:
    """The job of a move to rack lengths (n, 3), moved into the rack and bending limits first
    (the leading joint move from wherever the motors are does the travel)."""
    goal = np.asarray(lengths, dtype=float)
    if goal.shape != (robot.n_segments, 3) or not np.all(np.isfinite(goal)):
        raise ValueError(f"lengths must be finite with shape ({robot.n_segments}, 3)")
    goal = dk.limit_rack_lengths(robot, goal)
    return joint_move(robot, goal, goal, rate_hz=1.0 / period_s)


def mock_factory(robot: ExtensibleArm, relaxed_s: float = 0.5) -> Callable[[], HardwareInterface]:
    """Factory of one in-process MockHardware, made on the first call and then kept (its device
    persists across reconnects, like a board).

    It shares the GIL with the GUI, so its link timeout and watchdog are relaxed to
    ``relaxed_s``: a slow GUI callback must not read as a lost cable. Its motors start at the
    console's start pose (:func:`hw_bridge.extensible_jobs.mid_range_counts`, as the device
    emulator's ``--mid-range``), so arming, which holds where the encoders are, moves nothing.
    """
    made: list[HardwareInterface] = []

    def factory() -> HardwareInterface:
        if not made:
            from hw_bridge.extensible_jobs import mid_range_counts
            from hw_bridge.mock import MockHardware
            hw = MockHardware(robot)
            hw.config = dataclasses.replace(hw.config, link_timeout_s=relaxed_s,
                                            watchdog_s=relaxed_s)
            motors = hw.device.motors
            motors.position[:] = mid_range_counts(robot)
            motors.target[:] = motors.position
            made.append(hw)
        return made[0]
    return factory
