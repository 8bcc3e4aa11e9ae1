"""One face for both arms' loops, so the console core stops and moves either without asking which.

The console core (:mod:`console.core.console_core`) talks to the arm only through an
:class:`ArmSupervisor`: ``stop(reason)`` (the one safety route's last step), ``forward(state)``
(a new commanded state from the store, sent on only while the arm takes it), and what the
watcher reads (``alive``, ``failure``, ``link_fault``; ``view_age`` and ``restart`` for the
header and the "Restart control loop" button). There is one per arm kind:

* :class:`SoftArmSupervisor` over :class:`hw_bridge.soft_arm_process.ControlProcess`: STOP is
  its controlled ``stop_arm``; a commanded state becomes a ``goto`` only while the loop is armed,
  has a measurement and is idle (``FORWARD_PHASES``), and not before the loop has published a
  view after the latest STOP (so a command that was on its way cannot undo the STOP);
* :class:`ExtensibleSupervisor` over :class:`hw_bridge.extensible_process.ExtensibleProcess`:
  STOP makes the runner hold; every commanded state goes down as a set-point, and the runner
  follows it only while armed and idle (its own rule);
* :class:`NoArmSupervisor`: no hardware (kinematic simulation): the store's command is what is
  drawn, so there is nothing to stop or forward.

:func:`supervisor_for` picks the one for a console's services.
"""

from __future__ import annotations

import concurrent.futures as cf
import math
import threading
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from console.core.state import ArmState
from hw_bridge.link_supervisor import DISCONNECTED

if TYPE_CHECKING:
    from console.core.services import ConsoleServices

FORWARD_PHASES = ("idle", "released")  # the soft arm's loop turns commands into moves only then
SOFT_ARM_RESTING = ("idle", "released", "stopped")  # its phases that are not motion
SOFT_ARM_SOURCE = "control"  # the store's source of what the soft arm's loop measured
EXTENSIBLE_SOURCE = "runner"  # ... and of the extensible runner's own commands and reports


class ArmSupervisor(Protocol):
    """What the console core needs of an arm's loop, the same for both arm kinds."""

    @property
    def own_source(self) -> str:
        """The store source of the loop's own commands and reports (never forwarded back)."""
        ...

    def stop(self, reason: str) -> None:
        """End all motion of the loop now (a controlled stop; returns at once)."""
        ...

    def forward(self, state: ArmState) -> bool:
        """Send a new commanded state to the loop if it takes one now; whether it was sent."""
        ...

    @property
    def alive(self) -> bool:
        """Whether the loop's process runs (False before it started, too)."""
        ...

    def failure(self) -> str | None:
        """Why the loop's process ended on its own (None while it runs, before it started, or
        after a clean close)."""
        ...

    def link_fault(self) -> str | None:
        """The hardware fault the loop's newest view reports (None: none, or the operator's
        own Disconnect)."""
        ...

    def moving(self) -> bool:
        """Whether the loop's newest view shows the arm moving (a job, following, a task)."""
        ...

    def view_age(self) -> float:
        """Seconds since the loop's newest view arrived (``math.inf``: none yet)."""
        ...

    def restart(self) -> None:
        """Replace a dead or silent loop process by a new one (disarmed)."""
        ...


class SoftArmLoop(Protocol):
    """What :class:`SoftArmSupervisor` uses of
    :class:`hw_bridge.soft_arm_process.ControlProcess`."""

    view: Any
    failure: str | None

    @property
    def alive(self) -> bool: ...

    def stop_arm(self, reason: str = ...) -> cf.Future: ...

    def goto(self, q: Any) -> cf.Future: ...

    def view_age(self) -> float: ...

    def restart(self, timeout: float = ...) -> None: ...


class ExtensibleLoop(Protocol):
    """What :class:`ExtensibleSupervisor` uses of
    :class:`hw_bridge.extensible_process.ExtensibleProcess`."""

    view: Any
    failure: str | None

    @property
    def started(self) -> bool: ...

    def stop(self) -> Any: ...

    def setpoint(self, seq: int, delta: Any) -> None: ...

    def view_age(self) -> float: ...

    def restart(self, timeout: float = ...) -> None: ...


class SoftArmSupervisor:
    """The soft arm's control process behind :class:`ArmSupervisor` (see the module docstring).

    Args:
        ctl: The soft arm's control process (or a stand-in with the same members).
    """

    own_source = SOFT_ARM_SOURCE

    def __init__(self, ctl: SoftArmLoop) -> None:
        self.ctl = ctl
        self._lock = threading.Lock()
        self._stop_sent: cf.Future | None = None  # the latest STOP, until the loop applied it
        self._view_at_stop: Any = None  # the newest view when it was applied

    def stop(self, reason: str) -> None:
        fut = self.ctl.stop_arm(reason)
        with self._lock:
            self._stop_sent = fut
            self._view_at_stop = None
        fut.add_done_callback(self._stop_applied)

    def _stop_applied(self, fut: cf.Future) -> None:
        # Replies and views come in one queue, in order: a view that arrives after this one
        # was published after the loop applied the STOP.
        with self._lock:
            if fut is self._stop_sent:
                self._view_at_stop = self.ctl.view

    def _after_stop(self) -> bool:
        """Whether the loop has published a view since it applied the latest STOP."""
        with self._lock:
            fut, seen = self._stop_sent, self._view_at_stop
        if fut is None:
            return True
        if not fut.done():
            return False
        return self.ctl.view is not seen

    def forward(self, state: ArmState) -> bool:
        view = self.ctl.view
        c = None if view is None else view.snapshot.control
        if c is None or not c.armed or c.kappa_meas is None or c.phase not in FORWARD_PHASES:
            return False
        if not self._after_stop():
            return False
        self.ctl.goto(np.asarray(state.q))
        return True

    @property
    def alive(self) -> bool:
        return self.ctl.alive

    def failure(self) -> str | None:
        return None if self.ctl.alive else self.ctl.failure

    def link_fault(self) -> str | None:
        view = self.ctl.view
        fault = None if view is None else view.fault
        return None if not fault or fault == DISCONNECTED else str(fault)

    def moving(self) -> bool:
        view = self.ctl.view
        c = None if view is None else view.snapshot.control
        return c is not None and c.armed and c.phase not in SOFT_ARM_RESTING

    def view_age(self) -> float:
        return self.ctl.view_age()

    def restart(self) -> None:
        self.ctl.restart()


class ExtensibleSupervisor:
    """The extensible arm's runner process behind :class:`ArmSupervisor`.

    Args:
        runner: The extensible arm's runner process (or a stand-in with the same members). The
            in-process mock's starts on the first Execute: until then there is nothing to stop
            or to forward to.
    """

    own_source = EXTENSIBLE_SOURCE

    def __init__(self, runner: ExtensibleLoop) -> None:
        self.runner = runner

    def stop(self, reason: str) -> None:
        if self.runner.started:
            self.runner.stop()

    def forward(self, state: ArmState) -> bool:
        if not self.runner.started:
            return False
        self.runner.setpoint(state.seq, np.asarray(state.q, dtype=float))
        return True

    @property
    def alive(self) -> bool:
        return self.runner.started

    def failure(self) -> str | None:
        return None if self.runner.started else self.runner.failure

    def _snapshot(self) -> Any:
        view = self.runner.view
        return None if view is None else view.snapshot

    def link_fault(self) -> str | None:
        snap = self._snapshot()
        fault = None if snap is None else snap.fault
        return None if not fault or fault == DISCONNECTED else str(fault)

    def moving(self) -> bool:
        snap = self._snapshot()
        return snap is not None and (bool(snap.busy) or snap.state == "following")

    def view_age(self) -> float:
        return self.runner.view_age()

    def restart(self) -> None:
        self.runner.restart()


class NoArmSupervisor:
    """No hardware (kinematic simulation): the drawn arm is the command; nothing to stop."""

    own_source = "hardware"

    def stop(self, reason: str) -> None:
        """Nothing moves but the store's command, which the core's hold-to-run already ended."""

    def forward(self, state: ArmState) -> bool:
        return False

    @property
    def alive(self) -> bool:
        return True

    def failure(self) -> str | None:
        return None

    def link_fault(self) -> str | None:
        return None

    def moving(self) -> bool:
        return False

    def view_age(self) -> float:
        return math.inf

    def restart(self) -> None:
        raise RuntimeError("no control loop to restart (kinematic simulation)")


def supervisor_for(services: ConsoleServices) -> ArmSupervisor:
    """The supervisor of the loop ``services`` hold: the soft arm's control process, the
    extensible arm's runner, or none (kinematic simulation)."""
    if services.soft_control is not None:
        return SoftArmSupervisor(services.soft_control)
    if services.extensible_runner is not None:
        return ExtensibleSupervisor(services.extensible_runner)
    return NoArmSupervisor()
