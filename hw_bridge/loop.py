"""The 100 Hz loop runner: read -> update -> write, in real time or on a simulated clock.

* **Real time** (:meth:`LoopRunner.start`): a thread with absolute deadlines ``t0 + k period``
  (``time.perf_counter_ns``; sleep to ``deadline - spin``, then spin); deadlines missed by a
  long tick are counted as overruns and skipped, never caught up; optional ``SCHED_FIFO``.
* **Simulated clock** (:meth:`LoopRunner.run_sim`): one period per tick as fast as the CPU
  allows (sim-as-real; deterministic for a seeded device).

The loop thread is the only caller of the device and the stack. Commands from other threads go
through a queue (:meth:`LoopRunner.submit`) and run at the next tick; :attr:`LoopRunner.snapshot`
is swapped each tick (readers take no lock). Planning runs in another process
(:class:`ProcessPlanner`). Devices (:mod:`hw_bridge.loop_devices`): :class:`SimDevice`,
:class:`HardwareDevice`.
"""

from __future__ import annotations

import collections
import concurrent.futures as cf
import dataclasses
import logging
import queue
import threading
import time
from typing import Any, Callable, Protocol

import numpy as np
import numpy.typing as npt

from core.control.stack import Telemetry
from hw_bridge.realtime import set_fifo

Array = npt.NDArray[np.float64]
log = logging.getLogger(__name__)
_STATS_WINDOW = 65536  # ticks kept for percentiles (~11 min at 100 Hz)
_SLOW_MS = 1.0  # a tick that starts later than this, or works longer, is kept in slow_ticks


class Stack(Protocol):
    """What the loop updates (:class:`core.control.stack.ControlStack` or another runner)."""

    armed: bool

    def update(self, reading: Any, t: float, periods: int = 1) -> tuple[Any | None, Any]: ...

    def stop(self, t: float, reason: str) -> None: ...

    def device_fault(self, t: float, reason: str) -> Any | None:
        """The device failed: stop commanding; returns the control telemetry to publish
        (None: keep the last)."""
        ...


class Device(Protocol):
    """What the loop drives. ``t`` is the loop's time in seconds (ignored by real hardware)."""

    def read(self, t: float) -> Any | None: ...

    def write(self, commands: Array, t: float) -> bool: ...

    def cylinders(self) -> Array | None: ...


@dataclasses.dataclass(frozen=True)
class LoopStats:
    """Timing figures in milliseconds over the kept window; counts since start."""

    ticks: int
    overruns: int
    read_failures: int
    write_failures: int
    period_error_ms_p50: float
    period_error_ms_p99: float
    period_error_ms_max: float
    latency_ms_p99: float
    work_ms_p50: float
    work_ms_p99: float
    read_ms_p99: float
    update_ms_p99: float
    write_ms_p99: float


@dataclasses.dataclass(frozen=True)
class LoopSnapshot:
    """What the GUI reads: the last tick's control telemetry and timings (ms)."""

    tick: int
    t: float
    control: Telemetry | None
    period_ms: float
    work_ms: float
    read_ms: float
    update_ms: float
    write_ms: float
    overruns: int
    fault: str | None


@dataclasses.dataclass(frozen=True)
class SlowTick:
    """A tick that started late (> 1 ms), worked long (> 1 ms) or overran: where it went (ms).

    ``tick`` counts from 1 (the first tick); ``late_ms`` is the wake-up delay after the
    deadline (scheduler or GIL); ``drain_ms`` the queued commands; ``missed`` the deadlines
    skipped after it.
    """

    tick: int
    t: float
    late_ms: float
    drain_ms: float
    read_ms: float
    update_ms: float
    write_ms: float
    missed: int


class SimClock:
    """A nanosecond clock that only moves when told (sim-as-real and tests)."""

    def __init__(self, start_ns: int = 0):
        self.now_ns = start_ns

    def __call__(self) -> int:
        return self.now_ns

    def sleep_until(self, deadline_ns: int) -> None:
        self.now_ns = max(self.now_ns, deadline_ns)


class LoopRunner:
    """Runs ``device.read -> stack.update -> device.write`` every period.

    Args:
        device: A :class:`Device`.
        stack: The control stack (``update(reading, t, periods)``).
        period_s: Control period.
        clock_ns: Scheduling clock in ns: deadlines, lateness, overruns (real time:
            ``time.perf_counter_ns``; :class:`SimClock` for sim-as-real; tests inject one).
        sleep_until: ``deadline_ns -> None`` waiting until the clock reaches it (default: sleep
            to ``deadline - spin_ns`` then spin).
        spin_ns: Busy-wait margin before each deadline in real time.
        timer_ns: Clock for the read/update/write work timings (always real CPU time by
            default, also on the simulated clock, so sim runs report their real tick cost).
    """

    def __init__(self, device: Device, stack: Stack, period_s: float = 0.01,
                 clock_ns: Callable[[], int] = time.perf_counter_ns,
                 sleep_until: Callable[[int], None] | None = None, spin_ns: int = 300_000,
                 timer_ns: Callable[[], int] = time.perf_counter_ns):
        self.device, self.stack = device, stack
        self.timer_ns = timer_ns
        self.period_ns = round(period_s * 1e9)
        self.clock_ns = clock_ns
        self.spin_ns = spin_ns
        self._sleep_until = sleep_until or self._default_sleep
        self._commands: queue.SimpleQueue[tuple[Callable[[Any, float], Any], cf.Future]] = \
            queue.SimpleQueue()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._t0: int | None = None
        self._k = 0  # deadline index of the current tick
        self._last_start: int | None = None
        self._skipped = 0
        self.ticks = 0
        self.overruns = 0
        self.read_failures = 0
        self.write_failures = 0
        self.update_failures = 0
        self.fault: str | None = None
        self.scheduling = "not started"
        self._buf = np.zeros((6, _STATS_WINDOW))  # period err, latency, read, update, write, work
        self.slow_ticks: collections.deque[SlowTick] = collections.deque(maxlen=64)
        self.snapshot = LoopSnapshot(0, 0.0, None, 0.0, 0.0, 0.0, 0.0, 0.0, 0, None)
        # Every tick's row for the lab (core.labdata.ticks.TickRing; None: not kept). Filled
        # by this loop only; another thread drains it.
        self.tick_ring: Any = None

    # -- commands ------------------------------------------------------------------------------
    def submit(self, fn: Callable[[Any, float], Any]) -> cf.Future:
        """Queue ``fn(stack, t)`` for the loop thread; the future gets its result or error."""
        fut: cf.Future = cf.Future()
        self._commands.put((fn, fut))
        return fut

    def arm(self) -> cf.Future:
        return self.submit(lambda s, t: s.arm(self.device.cylinders()))

    def start_task(self) -> cf.Future:
        return self.submit(lambda s, t: s.start(t))

    def execute(self, plan: Any, center: npt.ArrayLike) -> cf.Future:
        return self.submit(lambda s, t: s.execute(plan, center, t))

    def goto(self, kappa: npt.ArrayLike) -> cf.Future:
        return self.submit(lambda s, t: s.goto(kappa, t))

    def stop_arm(self, reason: str = "operator STOP") -> cf.Future:
        return self.submit(lambda s, t: s.stop(t, reason))

    def disarm(self) -> cf.Future:
        return self.submit(lambda s, t: s.disarm())

    def _drain(self, t: float) -> None:
        while True:
            try:
                fn, fut = self._commands.get_nowait()
            except queue.Empty:
                return
            if not fut.set_running_or_notify_cancel():
                continue
            try:
                fut.set_result(fn(self.stack, t))
            except Exception as exc:  # noqa: BLE001 - reported to the caller through the future
                fut.set_exception(exc)

    # -- one tick ------------------------------------------------------------------------------
    def tick(self) -> None:
        """One read -> update -> write at the current deadline."""
        clock, timer = self.clock_ns, self.timer_ns
        start = clock()
        w0 = timer()
        if self._t0 is None:
            self._t0 = start
        deadline = self._t0 + self._k * self.period_ns
        t = (deadline - self._t0) / 1e9
        periods = 1 + self._skipped
        self._skipped = 0
        self._drain(t)
        t_read = timer()
        reading = self.device.read(t)
        t_upd = timer()
        commands = None
        if reading is None:
            self.read_failures += 1
            self.fault = getattr(self.device, "fault", None) or "device read failed"
            control = self.snapshot.control
            if self.stack.armed:
                control = self.stack.device_fault(t, f"device: {self.fault}") or control
        else:
            try:
                commands, control = self.stack.update(reading, t, periods)
            except Exception as exc:  # noqa: BLE001 - a failing part must not end the loop
                log.exception("control update failed at t = %.2f s", t)
                self.update_failures += 1
                self.fault = f"control update failed: {type(exc).__name__}: {exc}"
                control = self.stack.device_fault(t, self.fault) or self.snapshot.control
        t_write = timer()
        if commands is not None and not self.device.write(commands, t):
            self.write_failures += 1
            self.fault = getattr(self.device, "fault", None) or "device write failed"
            control = self.stack.device_fault(t, f"device: {self.fault}") or control
        end = timer()
        i = self.ticks % _STATS_WINDOW
        # Python floats (not numpy scalars read back from the buffer): the snapshot and the slow
        # ticks are pickled for the console 30 times a second, and a numpy scalar pickles ~50x
        # slower (64 slow ticks took ~0.5 ms, holding the GIL the loop wakes up to).
        period = 0.0 if self._last_start is None else (start - self._last_start) / 1e6
        err = 0.0 if self._last_start is None else period - periods * self.period_ns / 1e6
        late, read_ms = (start - deadline) / 1e6, (t_upd - t_read) / 1e6
        update_ms, write_ms = (t_write - t_upd) / 1e6, (end - t_write) / 1e6
        work_ms = (end - w0) / 1e6
        self._buf[:, i] = (err, late, read_ms, update_ms, write_ms, work_ms)
        self._last_start = start
        self.ticks += 1
        self.snapshot = LoopSnapshot(self.ticks, t, control, period, work_ms, read_ms, update_ms,
                                     write_ms, self.overruns, self.fault)
        # Next deadline; deadlines already passed are overruns, skipped rather than caught up.
        self._k += 1
        next_deadline = self._t0 + self._k * self.period_ns
        now = clock()
        missed = 0
        if now > next_deadline:
            missed = int((now - next_deadline) // self.period_ns + 1)
            self.overruns += missed
            self._skipped = missed
            self._k += missed
        if missed or late > _SLOW_MS or work_ms > _SLOW_MS:
            self.slow_ticks.append(SlowTick(self.ticks, t, late, (t_read - w0) / 1e6,
                                            read_ms, update_ms, write_ms, missed))
        ring = self.tick_ring
        if ring is not None:
            ring.add(self.ticks, t, reading, commands, control,
                     (late, period, work_ms, read_ms, update_ms, write_ms), missed)

    def next_deadline_ns(self) -> int:
        t0 = self.clock_ns() if self._t0 is None else self._t0
        return t0 + self._k * self.period_ns

    # -- simulated clock -----------------------------------------------------------------------
    def run_sim(self, seconds: float, until: Callable[[LoopSnapshot], bool] | None = None) -> int:
        """Tick on a simulated clock for ``seconds`` (or until ``until(snapshot)``); returns ticks.

        Requires ``clock_ns`` to be a :class:`SimClock`; the clock jumps to each deadline.
        """
        clock = self.clock_ns
        if not isinstance(clock, SimClock):
            raise TypeError("run_sim needs the runner built with clock_ns=SimClock()")
        n = round(seconds * 1e9 / self.period_ns)
        for i in range(n):
            clock.sleep_until(self.next_deadline_ns())
            self.tick()
            if until is not None and until(self.snapshot):
                return i + 1
        return n

    # -- real time -----------------------------------------------------------------------------
    def _default_sleep(self, deadline_ns: int) -> None:
        clock = self.clock_ns
        remaining = deadline_ns - clock() - self.spin_ns
        if remaining > 0:
            time.sleep(remaining / 1e9)
        while clock() < deadline_ns:
            pass

    def start(self, sched_priority: int | None = None) -> None:
        """Run ticks on a background thread at absolute deadlines until :meth:`stop`.

        ``sched_priority`` (1-99) asks Linux to run the loop thread under ``SCHED_FIFO`` so
        other processes cannot delay its deadlines; without the permission it runs normally.
        :attr:`scheduling` says which one it got.
        """
        if self._thread is not None:
            raise RuntimeError("loop already running")
        if isinstance(self.clock_ns, SimClock) and self._sleep_until == self._default_sleep:
            raise RuntimeError("a SimClock never advances by itself: use run_sim(), or give "
                               "sleep_until=clock.sleep_until")
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, args=(sched_priority,),
                                        name="control-loop-100Hz", daemon=True)
        self._thread.start()

    def _run(self, sched_priority: int | None = None) -> None:
        self.scheduling = "default (SCHED_OTHER)"
        if sched_priority:
            self.scheduling = set_fifo(sched_priority)
        self._t0 = None
        self._k = 0
        while not self._stop.is_set():
            if self._t0 is not None:
                self._sleep_until(self.next_deadline_ns())
            self.tick()

    def stop(self, timeout: float = 2.0) -> None:
        """Stop the loop thread (the last demands stay with the device)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def stats(self, last: int | None = None) -> LoopStats:
        """Percentiles over the kept window, or the ``last`` ticks only (cheaper: GUIs).

        Safe to call from any thread; values may be a tick old.
        """
        n = min(self.ticks, _STATS_WINDOW)
        if last is not None and last < n:
            end = self.ticks % _STATS_WINDOW
            b = (self._buf[:, end - last:end] if end >= last else
                 self._buf[:, (np.arange(end - last, end)) % _STATS_WINDOW])
            n = last
        else:
            b = self._buf[:, :n].copy()
        if n == 0:
            return LoopStats(0, 0, 0, 0, *([0.0] * 9))
        err = np.abs(b[0, 1:]) if n > 1 else np.zeros(1)
        (e50, e99), (p50, p99) = _percentiles(err[None], (50, 99)), _percentiles(b[1:], (50, 99))
        return LoopStats(self.ticks, self.overruns, self.read_failures, self.write_failures,
                         float(e50[0]), float(e99[0]), float(err.max()), float(p99[0]),
                         float(p50[4]), float(p99[4]), float(p99[1]), float(p99[2]),
                         float(p99[3]))


def _percentiles(rows: Array, qs: tuple[float, ...]) -> list[Array]:
    """``np.percentile(rows, q, axis=1)`` (linear interpolation) for each ``q``, with one
    partial sort for all of them: a fifth of the cost for the publisher's 30 calls a second."""
    n = rows.shape[1]
    pos = [q / 100.0 * (n - 1) for q in qs]
    lo = [int(p) for p in pos]
    hi = [min(i + 1, n - 1) for i in lo]
    part = np.partition(rows, sorted(set(lo + hi)), axis=1)
    return [part[:, i] + (p - i) * (part[:, j] - part[:, i]) for p, i, j in zip(pos, lo, hi)]

