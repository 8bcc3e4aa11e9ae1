"""Runs the extensible arm's motion paths on the motors at 100 Hz and reads the tip back.

:class:`ExtensibleRunner` drives one :class:`~hw_bridge.interface.HardwareInterface`
(:class:`~hw_bridge.interface.SerialHardware` to the Arduino Due or the pty emulator, or
:class:`~hw_bridge.mock.MockHardware`) through :class:`hw_bridge.loop.LoopRunner` (absolute
deadlines, overruns skipped): every tick reads the encoders, converts them to rack lengths
(L = U m), Delta (eq. 2) and the measured tip (forward kinematics), and writes one DEMAND.

* A job (:meth:`ExtensibleRunner.execute` a :class:`~core.planning.paths.MotionPath`, or
  :meth:`ExtensibleRunner.move_to` rack lengths) streams its motor counts by time (sample
  ``floor((t - t0) * rate_hz)``), preceded by a joint move from wherever the motors are to the
  path's first sample; after the last sample the final demand is held until the encoders are
  within ``settle_counts`` (or ``settle_timeout`` passes).
* Idle, the runner holds its last demand, or follows the console's newest commanded posture
  (through a :class:`PoseLink`) with rack and tip speeds within the robot's limits.
* :meth:`ExtensibleRunner.stop` holds position where the motors are. A hardware ERROR
  (link lost, watchdog, e-stop, ...) aborts the job and stops commanding; the snapshot reports
  the fault until :meth:`ExtensibleRunner.connect` reconnects.
* :attr:`ExtensibleRunner.snapshot` is an immutable :class:`RunnerSnapshot` replaced every tick
  (no lock for readers); the job's commanded and measured tips go into a :class:`JobTrace`.

Encoder zero. Incremental encoders read 0 where the board powered up, which is the retracted
(homed) pose: demands are ``U^-1 L`` counts minus those of the retracted pose
(:func:`home_counts`).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import threading
from concurrent.futures import Future
from typing import Any, Callable, Protocol

import numpy as np
import numpy.typing as npt

from core.kinematics import delta as dk
from core.planning.paths import MotionPath
from core.robots import ExtensibleArm
from hw_bridge.interface import HardwareInterface, LifecycleState, ReturnType
from hw_bridge.loop import LoopRunner

Array = npt.NDArray[np.float64]
Counts = npt.NDArray[np.int64]
_NOT_CONNECTED: Counts = np.zeros(0, dtype=np.int64)


def home_counts(robot: ExtensibleArm) -> Counts:
    """Absolute motor counts ``U^-1 L`` of the retracted pose, where the encoders read 0."""
    retracted = dk.robot_rack_lengths(robot, np.zeros((robot.n_segments, 3)))
    return dk.motor_counts_from_lengths(robot, retracted)


def measure(robot: ExtensibleArm, encoders: npt.ArrayLike,
            home: Counts) -> tuple[Array, Array, Array]:
    """Encoder counts (3n,) -> rack lengths (n, 3), Delta (n, 3) and tip (3,)."""
    lengths = dk.lengths_from_motor_counts(robot, np.asarray(encoders, dtype=float) + home)
    delta = dk.delta_from_actuators(lengths, robot.phi, robot.L0)
    return lengths, delta, dk.tip_position(robot, delta)


def joint_move(robot: ExtensibleArm, start: npt.ArrayLike, goal: npt.ArrayLike, *,
               rate_hz: float = 100.0, margin: float = 0.98) -> MotionPath:
    """Straight line in rack space from rack lengths ``start`` to ``goal`` (each (n, 3)).

    The rack box is convex, so every sample is within the limits. Timed like
    :func:`core.planning.paths.plan_path`: no rack faster than ``rack_speed`` and the tip (over a
    fine sub-sampling) no faster than ``tip_speed``, both scaled by ``margin``. The targets are
    the tips reached (errors 0).
    """
    a = np.clip(np.asarray(start, dtype=float), robot.rack_min, robot.rack_max)
    b = np.clip(np.asarray(goal, dtype=float), robot.rack_min, robot.rack_max)
    shape = (robot.n_segments, 3)
    if a.shape != shape or b.shape != shape:
        raise ValueError(f"start and goal must be rack lengths of shape {shape}")
    travel = float(np.abs(b - a).max())
    m = max(8, math.ceil(travel / 5e-4))
    s = np.linspace(0.0, 1.0, m + 1)
    sub = a + (b - a) * s[:, None, None]
    tips = dk.tip_position(robot, dk.delta_from_actuators(sub, robot.phi, robot.L0))
    # Racks, motors (m = U^-1 L: a proximal motor moves by the difference of two racks) and tip.
    travel = np.abs(np.diff(np.concatenate([sub, dk.motors_from_lengths(sub)], axis=1), axis=0))
    dt = np.maximum(travel.reshape(m, -1).max(axis=1) / (robot.rack_speed * margin),
                    np.linalg.norm(np.diff(tips, axis=0), axis=1) / (robot.tip_speed * margin))
    t_sub = np.concatenate([[0.0], np.cumsum(dt)])
    count = math.ceil(t_sub[-1] * rate_hz - 1e-9) + 1
    times = np.arange(count) / rate_hz
    lengths = a + (b - a) * np.interp(times, t_sub, s)[:, None, None]
    deltas = dk.delta_from_actuators(lengths, robot.phi, robot.L0)
    reached = dk.tip_position(robot, deltas)
    return MotionPath(times=times, targets=reached, tips=reached, deltas=deltas, lengths=lengths,
                      motor_counts=dk.motor_counts_from_lengths(robot, lengths),
                      errors=np.zeros(count), rate_hz=rate_hz, jumps=0)


class PoseLink(Protocol):
    """How the runner talks to an operator console (optional).

    ``setpoint()``: newest commanded posture (n, 3) and its sequence number (followed while
    idle); ``measured(delta)``: show the measured posture (while a job runs, or always if
    ``always_report``); ``settled(delta)``: a job ended there, make it the command (returns its
    sequence number).
    """

    always_report: bool

    def setpoint(self) -> tuple[int, Array] | None: ...

    def measured(self, delta: Array) -> None: ...

    def settled(self, delta: Array) -> int: ...


class StoreLink:
    """:class:`PoseLink` onto a console ``StateStore`` (duck-typed: command, report, request)."""

    def __init__(self, store: Any) -> None:
        self.store = store
        self.always_report = not getattr(store, "mirror_commands", True)

    def setpoint(self) -> tuple[int, Array]:
        cmd = self.store.command
        return cmd.seq, np.asarray(cmd.q)

    def measured(self, delta: Array) -> None:
        self.store.report(delta, "runner")

    def settled(self, delta: Array) -> int:
        return self.store.request(delta, "runner").seq


@dataclasses.dataclass
class JobTrace:
    """Per-sample record of one job; the loop writes index i before publishing ``count > i``."""

    times: Array             # (K,) s
    targets: Array           # (K, 3) tip targets
    commanded: Array         # (K, 3) tips of the demanded postures
    measured: Array          # (K, 3) tips from the encoders (NaN until written)


@dataclasses.dataclass(frozen=True)
class JobResult:
    """How a job ended. ``error``: measured final tip to the final target (m)."""

    job_id: int
    label: str
    ok: bool
    message: str
    final_tip: Array | None
    final_target: Array | None
    error: float | None


@dataclasses.dataclass(frozen=True)
class RunnerSnapshot:
    """What the UI reads; replaced (never mutated) every tick."""

    state: str               # disconnected | holding | following | running | settling | fault
    tick: int = 0
    job_id: int = 0
    label: str = ""
    sample: int = 0
    n_samples: int = 0
    measured_delta: Array | None = None
    measured_tip: Array | None = None
    fault: str | None = None
    message: str = ""
    trace: JobTrace | None = None
    trace_count: int = 0
    last_result: JobResult | None = None

    @property
    def progress(self) -> float:
        """Fraction of the job's samples streamed (1 once settled)."""
        return 0.0 if self.n_samples == 0 else min(1.0, self.sample / max(1, self.n_samples - 1))

    @property
    def busy(self) -> bool:
        return self.state in ("running", "settling")


@dataclasses.dataclass
class _Job:
    job_id: int
    label: str
    path: MotionPath
    t0: float
    trace: JobTrace
    counts: Counts           # (K, 3n) demands relative to home
    t_end: float | None = None
    written: int = 0


class _Device:
    """:class:`hw_bridge.loop.Device` over a HardwareInterface that may come and go."""

    def __init__(self) -> None:
        self.hw: HardwareInterface | None = None
        self.fault: str | None = None

    def read(self, t: float) -> Counts | None:
        """Encoder counts; an empty array when not connected; None on a hardware ERROR."""
        hw = self.hw
        if hw is None or hw.state is not LifecycleState.ACTIVE:
            return _NOT_CONNECTED
        if hw.read() is not ReturnType.OK:
            self.fault = hw.fault or "hardware read failed"
            return None
        return hw.positions()

    def write(self, commands: Counts, t: float) -> bool:
        hw = self.hw
        if hw is None or hw.write(commands) is not ReturnType.OK:
            self.fault = (hw.fault if hw else None) or "hardware write failed"
            return False
        return True

    def cylinders(self) -> Array | None:
        pos = None if self.hw is None else self.hw.positions()
        return None if pos is None else np.asarray(pos, dtype=float)


class _Streamer:
    """The loop's ``stack``: decides each tick's demand (loop thread only)."""

    def __init__(self, robot: ExtensibleArm, period_s: float, link: PoseLink | None,
                 settle_counts: int, settle_timeout: float, margin: float = 0.98) -> None:
        self.robot, self.period, self.link = robot, period_s, link
        self.settle_counts, self.settle_timeout = settle_counts, settle_timeout
        self.v_rack, self.v_tip = robot.rack_speed * margin, robot.tip_speed * margin
        self.home = home_counts(robot)
        self.armed = False
        self.hold_L: Array | None = None
        self.track_L: Array | None = None
        self.seen_seq: int | None = None
        self.job: _Job | None = None
        self.recent: _Job | None = None  # the running or last job, for the snapshot
        self.fault: str | None = None
        self.message = "not connected"
        self.last_result: JobResult | None = None
        self.on_result: Callable[[JobResult], None] = lambda r: None
        self.measured_L: Array | None = None
        self.snapshot = RunnerSnapshot("disconnected", message=self.message)

    def _counts(self, lengths: Array) -> Counts:
        return dk.motor_counts_from_lengths(self.robot, lengths) - self.home

    def _delta(self, lengths: Array) -> Array:
        return dk.delta_from_actuators(lengths, self.robot.phi, self.robot.L0)

    def _tip(self, lengths: Array) -> Array:
        return dk.tip_position(self.robot, self._delta(lengths))

    # -- commands (loop thread) ------------------------------------------------------------
    def connected(self, encoders: Counts, follow: bool) -> None:
        self.armed, self.fault = True, None
        self.hold_L = self.measured_L = measure(self.robot, encoders, self.home)[0]
        self.track_L, self.message = None, "holding"
        self.seen_seq = -1 if follow else self._setpoint_seq()

    def _setpoint_seq(self) -> int | None:
        sp = self.link.setpoint() if self.link else None
        return None if sp is None else sp[0]

    def start_job(self, job_id: int, label: str, path: MotionPath, t: float) -> None:
        if not self.armed or self.measured_L is None:
            why = f"not started: {self.fault or self.message}"
            self._finish(JobResult(job_id, label, False, why, None, None, None))
            return
        if self.job is not None:
            self._end_job(False, f"replaced by job {job_id}")
        start = np.clip(self.measured_L, self.robot.rack_min, self.robot.rack_max)
        if np.abs(path.lengths[0] - start).max() > 5e-4:  # join it from where the motors are
            lead = joint_move(self.robot, start, path.lengths[0], rate_hz=path.rate_hz)
            path = _concat(lead, path)
        trace = JobTrace(path.times, path.targets, path.tips,
                         np.full((len(path.times), 3), np.nan))
        self.job = self.recent = _Job(job_id, label, path, t, trace,
                                      path.motor_counts - self.home)
        self.track_L = None
        self.message = f"{label}: running"

    def halt(self, t: float) -> None:
        """Operator stop: hold where the motors are."""
        if self.measured_L is not None:
            self.hold_L = np.clip(self.measured_L, self.robot.rack_min, self.robot.rack_max)
        self.track_L = None
        if self.job is not None:
            self._end_job(False, "stopped by operator; holding position")
        self._settle_link()

    def stop(self, t: float, reason: str = "stopped") -> None:
        """Called by the loop on a device read/write failure: stop commanding, report the fault."""
        self.armed = False
        self.fault = reason.removeprefix("device: ")
        if self.job is not None:
            self._end_job(False, f"aborted: {self.fault}")
        self.message = f"fault: {self.fault}"

    def _end_job(self, ok: bool, message: str) -> None:
        job = self.job
        assert job is not None
        self.job = None
        tip = target = err = None
        if self.measured_L is not None:
            tip = self._tip(self.measured_L)
            target = job.path.targets[-1]
            err = float(np.linalg.norm(tip - target))
        self.message = f"{job.label}: {message}"
        self._finish(JobResult(job.job_id, job.label, ok, message, tip, target, err))

    def _finish(self, result: JobResult) -> None:
        self.last_result = result
        self.on_result(result)

    def _settle_link(self) -> None:
        if self.link is not None and self.hold_L is not None:
            self.seen_seq = self.link.settled(self._delta(self.hold_L))

    # -- one tick --------------------------------------------------------------------------
    def update(self, encoders: Counts, t: float,
               periods: int = 1) -> tuple[Counts | None, RunnerSnapshot]:
        if encoders.size == 0:
            self.armed, self.measured_L = False, None
            state = "fault" if self.fault else "disconnected"
            self.snapshot = dataclasses.replace(self.snapshot, state=state, fault=self.fault,
                                                message=self.message, last_result=self.last_result)
            return None, self.snapshot
        L, delta, tip = measure(self.robot, encoders, self.home)
        self.measured_L = L
        job = self.job
        if job is None:
            demand, state = self._idle(periods)
        else:
            demand, state = self._stream(job, encoders, tip, t)
        if self.link is not None and (job is not None or self.link.always_report):
            self.link.measured(delta)
        j, tick = self.recent, self.snapshot.tick + 1
        if j is None:
            self.snapshot = RunnerSnapshot(state, tick, measured_delta=delta, measured_tip=tip,
                                           fault=self.fault, message=self.message)
        else:
            k = len(j.path.times)
            self.snapshot = RunnerSnapshot(
                state, tick, j.job_id, j.label, min(int((t - j.t0) * j.path.rate_hz), k - 1), k,
                delta, tip, self.fault, self.message, j.trace, j.written, self.last_result)
        return demand, self.snapshot

    def _idle(self, periods: int) -> tuple[Counts, str]:
        assert self.hold_L is not None
        sp = self.link.setpoint() if self.link else None
        if sp is not None and sp[0] != self.seen_seq:
            self.seen_seq = sp[0]
            self.track_L = np.clip(dk.robot_rack_lengths(self.robot, sp[1]), self.robot.rack_min,
                                   self.robot.rack_max)
        if self.track_L is None:
            return self._counts(self.hold_L), "holding"
        step = self.track_L - self.hold_L
        far = max(float(np.abs(step).max()), float(np.abs(dk.motors_from_lengths(step)).max()))
        if far < 1e-7:
            self.hold_L, self.track_L = self.track_L, None
            return self._counts(self.hold_L), "holding"
        dt = self.period * periods
        s = min(1.0, self.v_rack * dt / far)
        nxt = self.hold_L + s * step
        moved = float(np.linalg.norm(self._tip(nxt) - self._tip(self.hold_L)))
        if moved > self.v_tip * dt:
            nxt = self.hold_L + s * (self.v_tip * dt / moved) * step
        self.hold_L = nxt
        return self._counts(nxt), "following"

    def _stream(self, job: _Job, enc: Counts, tip: Array, t: float) -> tuple[Counts, str]:
        k_last = len(job.path.times) - 1
        k = min(int((t - job.t0) * job.path.rate_hz + 1e-9), k_last)
        while job.written <= k:  # skipped samples (overruns) get this tick's measurement
            job.trace.measured[job.written] = tip
            job.written += 1
        demand = job.counts[k]
        if k < k_last:
            return demand, "running"
        job.t_end = t if job.t_end is None else job.t_end
        off = int(np.abs(enc - demand).max())
        if off <= self.settle_counts or t - job.t_end >= self.settle_timeout:
            self.hold_L = job.path.lengths[-1]
            ok = off <= self.settle_counts
            self._end_job(ok, "done" if ok else f"did not settle ({off} counts off)")
            self._settle_link()
            return demand, "holding"
        return demand, "settling"


def _concat(a: MotionPath, b: MotionPath) -> MotionPath:
    """``a`` then ``b`` (b's first sample follows a's last one period later)."""
    dt = 1.0 / a.rate_hz
    cat = lambda x, y: np.concatenate([x, y])  # noqa: E731
    return MotionPath(times=cat(a.times, b.times + a.times[-1] + dt),
                      targets=cat(a.targets, b.targets), tips=cat(a.tips, b.tips),
                      deltas=cat(a.deltas, b.deltas), lengths=cat(a.lengths, b.lengths),
                      motor_counts=cat(a.motor_counts, b.motor_counts),
                      errors=cat(a.errors, b.errors), rate_hz=a.rate_hz, jumps=a.jumps + b.jumps)


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
        follow: On connect, move to the link's commanded posture at once (else wait for a new one).
    """

    def __init__(self, robot: ExtensibleArm, hardware_factory: Callable[[], HardwareInterface],
                 *, link: PoseLink | None = None, period_s: float | None = None,
                 settle_counts: int = 3, settle_timeout: float = 3.0,
                 follow: bool = True) -> None:
        if getattr(robot, "kind", None) != "delta":
            raise ValueError(f"robot must be an extensible (delta) arm, got {type(robot).__name__}")
        from hw_bridge.config import BridgeConfig
        self.robot = robot
        self.factory = hardware_factory
        self.follow = follow
        self.period_s = period_s or BridgeConfig.from_robot(robot).period_s
        self.device = _Device()
        self.streamer = _Streamer(robot, self.period_s, link, settle_counts, settle_timeout)
        self.streamer.on_result = self._on_result
        # Short spin: streaming position demands needs no sub-0.1 ms deadlines; saves CPU.
        self.loop = LoopRunner(self.device, self.streamer, self.period_s,  # type: ignore[arg-type]
                               spin_ns=100_000)
        self._ids = itertools.count(1)
        self._results: dict[int, JobResult] = {}
        self._done = threading.Condition()
        self._start_lock = threading.Lock()
        self.connecting: Future | None = None  # the first connect, queued by start()

    @classmethod
    def from_app(cls, app: Any) -> "ExtensibleRunner":
        """The console's runner: ``app.extensible_runner`` if set, else one built on
        ``app.hardware_factory`` (if the app has one) or an in-process MockHardware, kept on
        ``app.extensible_runner``. Not started: call :meth:`start`."""
        runner = getattr(app, "extensible_runner", None)
        if runner is None:
            factory = getattr(app, "hardware_factory", None) or mock_factory(app.robot)
            link = StoreLink(app.store)
            runner = cls(app.robot, factory, link=link, follow=not link.always_report)
            app.extensible_runner = runner
        return runner

    # -- lifecycle -------------------------------------------------------------------------
    @property
    def started(self) -> bool:
        return self.loop.running

    def start(self) -> "ExtensibleRunner":
        """Start the 100 Hz thread and connect (idempotent; returns at once)."""
        with self._start_lock:
            if not self.loop.running:
                self.loop.start()
                self.connecting = self.connect()
        return self

    def connect(self) -> Future:
        """(Re)configure and activate the hardware from the factory, on the loop thread."""
        def run(stack: _Streamer, t: float) -> str | None:
            old = self.device.hw
            if old is not None:
                old.cleanup()
            hw = self.device.hw = self.factory()
            stack.fault, stack.message = None, "connecting"
            for step in (hw.configure, hw.activate):
                if step() is not ReturnType.OK:
                    stack.fault = hw.fault or f"{step.__name__} failed"
                    stack.message = f"fault: {stack.fault}"
                    return stack.fault
            pos = hw.positions()
            assert pos is not None
            stack.connected(pos, self.follow)
            return None
        return self.loop.submit(run)

    def close(self) -> None:
        """Disarm and release the hardware, stop the thread (and a MockHardware's device)."""
        if self.loop.running:
            try:  # the control thread is the one that talks to the hardware
                self.loop.submit(lambda s, t: self.device.hw and self.device.hw.cleanup()).result(2)
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
        if path.motor_counts.shape[1:] != (3 * self.robot.n_segments,) or len(path.times) < 1:
            raise ValueError("path must have motor counts of shape "
                             f"(K, {3 * self.robot.n_segments})")
        job_id = next(self._ids)
        self.loop.submit(lambda s, t: s.start_job(job_id, label, path, t))
        return job_id

    def move_to(self, lengths: npt.ArrayLike, label: str = "move") -> int:
        """Queue a joint move from wherever the motors are to rack lengths (n, 3)."""
        goal = np.asarray(lengths, dtype=float)
        if goal.shape != (self.robot.n_segments, 3) or not np.all(np.isfinite(goal)):
            raise ValueError(f"lengths must be finite with shape ({self.robot.n_segments}, 3)")
        goal = np.clip(goal, self.robot.rack_min, self.robot.rack_max)
        path = joint_move(self.robot, goal, goal, rate_hz=1.0 / self.period_s)
        return self.execute(path, label)  # the leading joint move does the travel

    def stop(self) -> Future:
        """Hold position (aborts the running job)."""
        return self.loop.submit(lambda s, t: s.halt(t))

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
    def snapshot(self) -> RunnerSnapshot:
        """Newest telemetry (any thread)."""
        return self.streamer.snapshot


def mock_factory(robot: ExtensibleArm, relaxed_s: float = 0.5) -> Callable[[], HardwareInterface]:
    """Factory of one in-process MockHardware, made on the first call and then kept (its device
    persists across reconnects, like a board).

    It shares the GIL with the GUI, so its link timeout and watchdog are relaxed to
    ``relaxed_s``: a slow GUI callback must not read as a lost cable.
    """
    made: list[HardwareInterface] = []

    def factory() -> HardwareInterface:
        if not made:
            from hw_bridge.mock import MockHardware
            hw = MockHardware(robot)
            hw.config = dataclasses.replace(hw.config, link_timeout_s=relaxed_s,
                                            watchdog_s=relaxed_s)
            made.append(hw)
        return made[0]
    return factory
