"""The console's headless core, so what stops the arm never depends on which panels exist.

:class:`ConsoleCore` owns all motion of the console for either arm (no viser here: panels and
the header render its state and call its methods):

* **One safety route.** :meth:`ConsoleCore.stop_motion` is THE call that ends motion: it refuses
  every motion started or queued before it (a stop *generation*), stops the demo motion, ends
  all jogging (:class:`~console.core.hold_to_run.HoldToRun` cancelled with its latch), stops the
  arm's loop through its :class:`~console.core.arm_supervisor.ArmSupervisor`, drops motions
  waiting in the core (an "execute once planned"), records it and keeps :attr:`last_stop`.
  STOP (any browser, Esc), the operator's lease lost / released / taken over (an
  :class:`~console.core.access.AccessControl` listener), a held jog whose renewals stopped
  (hold-to-run expiry), a link fault and a dead loop process (the watcher in :meth:`tick`) all
  end here, the same for both arms.
* **Jog speed.** Held jogs and the Jog panel's set-points run at the operator's jog speed
  (``hold.jog_speed``, started at the arm model's ``jog_speed``: 20 mm/s at the extensible
  arm's tip), never a panel's choice; the Jog panel's field only asks
  ``hold.set_jog_speed``.
* **Motion routes.** New commanded states in the store (jog, sliders, Straighten, set-points,
  the demo) that are not the loop's own reach the arm through ``arm.forward`` (the supervisor
  decides whether the arm takes one now); never one made at or before the latest STOP, and
  never STOP's own "stay here" command. Panels start other motions through
  :meth:`start_motion` / :meth:`run_if_current` / :meth:`run_expected`, which run under the
  same lock as :meth:`stop_motion`, so no move is ever queued behind a STOP.

:meth:`tick` (forwarding and the watcher) runs on the core's thread (:meth:`start`); tests call
it themselves on a fake clock.
"""

from __future__ import annotations

import collections
import dataclasses
import logging
import threading
import time
from typing import Any, Callable, Protocol, TypeVar

from console.core.access import AccessControl, Operator
from console.core.arm_supervisor import ArmSupervisor, supervisor_for
from console.core.hold_to_run import STOP_SOURCE, HoldToRun
from console.core.services import ConsoleServices
from console.core.state import ArmState, StateStore

log = logging.getLogger(__name__)

T = TypeVar("T")
TICK_S = 0.02  # the watcher's period (forwarding wakes at once on each new command)
STOP_LOG = 100  # stops kept in ConsoleCore.stop_log


class MotionStopped(RuntimeError):
    """A motion asked for before the latest STOP: it was not started."""


class ActionLog(Protocol):
    """What the core uses of :class:`console.recording.recorder.Recorder`."""

    def action(self, what: str, client: Any = None, **extra: Any) -> None: ...


@dataclasses.dataclass(frozen=True)
class StopRecord:
    """One end of motion: ``at`` on the core's clock, ``wall`` epoch seconds, why, and who
    (a name; "server" for the console itself)."""

    at: float
    wall: float
    reason: str
    who: str


class ConsoleCore:
    """The console's motion and safety for one arm (see the module docstring).

    Args:
        store: The console's state store.
        services: The loops the console runs (the arm's supervisor comes from them, unless
            ``arm`` is given).
        access: The operator lock; a change of holder that takes control from someone stops.
        recorder: Where stops are recorded (``recorder.action(text, client)``).
        arm: The arm's loop behind :class:`ArmSupervisor` (default: from ``services``).
        clock: Monotonic time source of the core and its hold-to-run (tests pass a fake one;
            it must be the one ``access`` uses, since hold-to-run reads its heartbeats).
        hold: Extra :class:`HoldToRun` arguments (``expiry``, ``rate_hz``, ...); ``jog_speed``
            defaults to the arm model's (the Jog panel's speed a class can follow).
    """

    def __init__(self, store: StateStore, services: ConsoleServices, access: AccessControl,
                 recorder: ActionLog, *, arm: ArmSupervisor | None = None,
                 clock: Callable[[], float] = time.monotonic, **hold: Any) -> None:
        self.store = store
        self.services = services
        self.access = access
        self.recorder = recorder
        self.arm: ArmSupervisor = arm if arm is not None else supervisor_for(services)
        self.clock = clock
        hold.setdefault("jog_speed", store.model.jog_speed)  # the arm's (extensible: 20 mm/s)
        self.hold = HoldToRun(store, allowed=access.is_operator, heard=access.last_heard,
                              clock=clock, on_expired=self._on_hold_expired, **hold)
        self._lock = threading.RLock()
        self._generation = 0
        self._stop_seq = -1  # commands at or before this seq are never forwarded
        self._held = False  # an explicit STOP holds the arm until the next motion
        self._rested = False  # the loop's view was seen at rest since that STOP
        self._expected: set[str] = set()
        self._forwarded_seq = store.command.seq  # commands from before the core are not sent
        self._seen_fault: str | None = None
        self._seen_death: str | None = None
        self.stops = 0
        self.stop_log: collections.deque[StopRecord] = collections.deque(maxlen=STOP_LOG)
        self._quit = threading.Event()
        self._thread: threading.Thread | None = None
        access.add_listener(self._on_control_change)

    # -- the one safety route ----------------------------------------------------------------

    def stop_motion(self, reason: str, who: Any = None, *, latch: bool = True) -> None:
        """End all motion now (any thread, anyone): see the module docstring.

        ``latch``: a jog button still held stays dead until it is released (STOP, a lost lease,
        a link fault); False when the jog's own renewals stopped (a late renewal may then start
        a new jog, as a fresh press would).
        """
        with self._lock:
            self._generation += 1
            self._expected.clear()
            if self.services.demo is not None:
                self._quietly(self.services.demo.stop, reason)
            self.hold.cancel(latch=latch)
            self._stop_seq = self.store.command.seq  # STOP's own command and all before it
            self._quietly(self.arm.stop, reason)
            if "stop" in reason.lower() and not self._held:
                self._held, self._rested = True, False
            self.stops += 1
            self.stop_log.append(StopRecord(self.clock(), time.time(), reason,
                                            self.access.name_of(who)))
        self.recorder.action(f"STOP: {reason}", who)

    @staticmethod
    def _quietly(fn: Callable[[str], Any], reason: str) -> None:
        try:
            fn(reason)
        except Exception:  # one broken stop must not keep the others from running
            log.exception("stopping with %r failed", fn)

    @property
    def last_stop(self) -> StopRecord | None:
        """The latest stop (None: none yet)."""
        with self._lock:
            return self.stop_log[-1] if self.stop_log else None

    @property
    def stop_generation(self) -> int:
        """How many stops there were; a motion asked for under an older one must not start."""
        with self._lock:
            return self._generation

    @property
    def holding_after_stop(self) -> bool:
        """Whether an explicit STOP holds the arm (until the next motion: a jog, a set-point,
        a started motion, or the arm seen moving *again*: the loop's view is seen at rest after
        the STOP first, since the views that arrive just after it still show the motion STOP
        ended, which would otherwise read as a new one and end the hold at once)."""
        with self._lock:
            if self._held:
                moving = self.arm.moving()
                if self.hold.active or (moving and self._rested):
                    self._held = False
                elif not moving:
                    self._rested = True
            return self._held

    def _on_control_change(self, new: Operator | None, previous: Operator | None,
                           reason: str) -> None:
        who = new if new is not None else previous
        self.recorder.action(reason, None if who is None else who.client_id)
        if previous is not None:  # the operator left or changed: the arm makes a controlled stop
            self.stop_motion(reason)

    def _on_hold_expired(self, reason: str) -> None:
        self.stop_motion(reason, latch=False)

    # -- motion routes -----------------------------------------------------------------------

    def start_motion(self, start: Callable[[], T]) -> T:
        """Run ``start()`` (which queues a motion on the arm) as a new motion: serialised with
        :meth:`stop_motion`, and it ends "holding after STOP"."""
        with self._lock:
            self._held = False
            return start()

    def run_if_current(self, generation: int, start: Callable[[], T]) -> T:
        """:meth:`start_motion` for a motion asked for under stop ``generation``
        (:attr:`stop_generation` then).

        Raises:
            MotionStopped: a STOP came since; nothing ran.
        """
        with self._lock:
            if generation != self._generation:
                raise MotionStopped("stopped")
            return self.start_motion(start)

    def expect_motion(self, name: str) -> None:
        """A motion named ``name`` will start once something is ready (e.g. "execute the path
        once planned"); any STOP before :meth:`run_expected` cancels it."""
        with self._lock:
            self._expected.add(name)

    def drop_expected(self, name: str) -> None:
        with self._lock:
            self._expected.discard(name)

    def is_expected(self, name: str) -> bool:
        with self._lock:
            return name in self._expected

    def run_expected(self, name: str, start: Callable[[], Any]) -> bool:
        """Start the expected motion ``name`` now if no STOP cancelled it; whether it ran."""
        with self._lock:
            if name not in self._expected:
                return False
            self._expected.discard(name)
            self.start_motion(start)
            return True

    def forward(self, state: ArmState) -> bool:
        """Send ``state`` (a new command) to the arm if it may go: not the loop's own, not
        STOP's, not from before the latest STOP, and the arm takes it; whether it was sent."""
        with self._lock:
            if state.seq <= self._stop_seq or state.source in (self.arm.own_source, STOP_SOURCE):
                return False
            sent = self.arm.forward(state)
            self._held = self._held and not sent  # the arm takes a new command: it moves again
            return sent

    def restart_loop(self, who: Any = None) -> None:
        """Replace the arm's loop process with a new one, disarmed (blocks for seconds): motion
        ends first through :meth:`stop_motion`; the new loop's failure and faults are news again.

        Raises:
            RuntimeError: the new loop process did not start (the reason is in the message).
        """
        self.recorder.action("restart the control loop", who)
        self.stop_motion("control loop restarted", who)
        self.arm.restart()
        with self._lock:
            self._seen_fault = None
            self._seen_death = None

    # -- the core's thread: forwarding and the watcher ---------------------------------------

    def tick(self) -> None:
        """Forward the newest command if it is new, then watch the arm's loop: a new link fault
        or a loop process that died stops motion (once per event, with the reason)."""
        cmd = self.store.command
        if cmd.seq != self._forwarded_seq:
            self._forwarded_seq = cmd.seq
            try:
                self.forward(cmd)
            except Exception:
                log.exception("forwarding command #%d failed", cmd.seq)
        fault = self.arm.link_fault()
        if fault != self._seen_fault:
            self._seen_fault = fault
            if fault:
                self.stop_motion(f"link lost: {fault}")
        died = self.arm.failure()
        if died != self._seen_death:
            self._seen_death = died
            if died:
                self.stop_motion(f"control loop died: {died}")

    def start(self) -> ConsoleCore:
        """Start hold-to-run and the core's thread (idempotent)."""
        self.hold.start()
        if self._thread is None or not self._thread.is_alive():
            self._quit.clear()
            self._thread = threading.Thread(target=self._run, name="console-core", daemon=True)
            self._thread.start()
        return self

    def stop(self, timeout: float = 2.0) -> None:
        """Stop the core's threads (motion is not stopped: call :meth:`stop_motion` first)."""
        self._quit.set()
        self.hold.stop(timeout)
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None

    def _run(self) -> None:
        while not self._quit.is_set():
            self.store.wait_command(self._forwarded_seq, timeout=TICK_S)
            if self._quit.is_set():
                break
            try:
                self.tick()
            except Exception:  # the watcher must outlive a bad view
                log.exception("console core tick failed")
                self._quit.wait(TICK_S)
