"""The operator lease's heartbeat: probe the operator's tab, revoke control when it goes silent.

:class:`LeaseMonitor` is the viser side of ``console.core.access.AccessControl``: it needs a live
server and its clients, while the lock itself stays testable without a browser.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any, Callable

import viser

from console.core.access import AccessControl
from console.core.lease_limits import LeaseStatus

log = logging.getLogger(__name__)


class SilenceWarning:
    """The operator's own notice that their browser is slow to answer, before the lease lapses.

    :meth:`update` with each :class:`LeaseStatus` shows it on the holder's tab once their
    silence passes ``warn_after`` ("Your browser has been silent for 1.5 s; the arm stops at
    3 s"); when the tab is heard again it says for how long it was silent and closes itself a
    few seconds later; when control goes (the lease lapsed, released, taken) it is removed (the
    app's "Control released" notice says the rest). A silent tab may only draw the notice once
    it catches up, so the after-the-fact sentence is the one most operators read.
    """

    CLOSE_AFTER_S = 6.0

    def __init__(self) -> None:
        self.shown = 0  # warnings shown so far (for tests and logs)
        self._client_id: int | None = None
        self._handle: Any = None
        self._worst = 0.0
        self._limit = 0.0

    @property
    def active(self) -> bool:
        """Whether a warning is showing now (not yet cleared)."""
        return self._handle is not None

    def update(self, client: Any, status: LeaseStatus) -> None:
        """Show, refresh or clear the warning for ``client`` (the holder's handle, or None)."""
        holder = status.holder
        same = (holder is not None and client is not None
                and client.client_id == holder.client_id == self._client_id)
        if self._handle is not None and not same:
            self._remove()
        if client is None or not status.warning:
            if self._handle is not None:
                self._heard()
            return
        self._worst = max(self._worst, status.silent_for)
        self._limit = status.limit
        if self._handle is None:
            try:
                self._handle = client.add_notification(
                    "Your browser is slow to answer", status.sentence(), color="yellow",
                    loading=True, with_close_button=False, auto_close_seconds=None)
            except Exception:  # noqa: BLE001 - a client that just left
                log.debug("lease warning to client %s failed", client.client_id)
                return
            self._client_id = client.client_id
            self.shown += 1
            log.info("operator's tab silent for %.1f s (lease %.1f s)", status.silent_for,
                     status.limit)

    def _heard(self) -> None:
        """The tab answered: say for how long it was silent, then close by itself."""
        handle, self._handle = self._handle, None
        try:
            handle.title = "Your browser answers again"
            handle.body = (f"It was silent for {self._worst:.1f} s; the arm stops at "
                           f"{self._limit:g} s. Close other busy tabs or programs.")
            handle.loading = False
            handle.with_close_button = True
            handle.auto_close_seconds = self.CLOSE_AFTER_S
        except Exception:  # noqa: BLE001 - a client that just left
            log.debug("lease warning update failed")
        self._client_id, self._worst = None, 0.0

    def _remove(self) -> None:
        handle, self._handle = self._handle, None
        self._client_id, self._worst = None, 0.0
        try:
            handle.remove()
        except Exception:  # noqa: BLE001 - a client that just left
            log.debug("lease warning removal failed")


class LeaseMonitor:
    """Keeps the operator's lease alive by probing their tab; revokes it on silence or close.

    A thread probes the holder's tab with a localStorage read (a JavaScript round trip)
    bounded so that the lease expires at most ``lease_s`` after the last answer, and from
    ``warn_s`` of silence on shows the operator a :class:`SilenceWarning` (an unanswered probe
    is re-sent at that moment; answers come in order, so nothing is lost); the answers are also
    the heartbeats that keep a set-point jog moving (it holds when the last one is over 300 ms
    old, see ``console.core.hold_to_run``), so while ``busy()`` (a jog is running) the tab is probed
    every ``probe_period`` s (0.1), otherwise every ``idle_period`` s (1.0), and only while
    ``needed()`` (the operator's motion needs their tab: the arm moving or a jog held; a tab
    that never answered yet, or is being warned, is probed regardless): each probe makes
    viser's client draw the 3D scene for a quarter of a second (a message that is not GUI-only
    opens its render window, and the answer is sent from the next frame), so probing a still
    console ten times a second kept its page drawing without pause, which a browser without a
    GPU pays with a whole core; a closed tab is also caught at once by
    ``server.on_client_disconnect``. On a desk console
    (``first_client_takes_control``) a tab whose lease lapsed by silence -- a software-rendered
    page busy for seconds -- is probed too and gets control back when it answers (the arm
    stopped when the lease lapsed and stays stopped); so is, in any mode, a tab whose lease
    lapsed before it ever answered (a page still loading).
    """

    def __init__(self, server: viser.ViserServer, access: AccessControl,
                 probe_period: float = 0.1, idle_period: float = 1.0,
                 busy: Callable[[], bool] = lambda: True,
                 needed: Callable[[], bool] = lambda: True) -> None:
        if not 0 < probe_period <= idle_period:
            raise ValueError("need 0 < probe_period <= idle_period (s)")
        self.server = server
        self.access = access
        self.probe_period = probe_period
        self.idle_period = idle_period
        self.busy = busy
        self.needed = needed
        self.probes = 0
        self.quiet_steps = 0  # steps that kept a still console's lease without a round trip
        self.warning = SilenceWarning()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        server.on_client_disconnect(self._on_disconnect)

    def _on_disconnect(self, client: viser.ClientHandle) -> None:
        holder = self.access.holder
        if holder is not None and holder.client_id == client.client_id:
            self.access.revoke(f"{holder.name}'s tab closed or lost its connection",
                               client.client_id)
        self.access.forget(client)

    def start(self) -> None:
        if self._thread is None or not self._thread.is_alive():
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="console-lease", daemon=True)
            self._thread.start()

    def stop(self, timeout: float = 3.0) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None

    def _run(self) -> None:
        last = float("-inf")
        while not self._stop.wait(self.probe_period):
            now = time.monotonic()
            if self.due(now - last):
                last = now
                self.step()

    def due(self, since_last: float) -> bool:
        """Whether to probe now, ``since_last`` s after the last probe was sent: every
        ``probe_period`` while ``busy()``, else every ``idle_period``."""
        return since_last >= (self.probe_period if self.busy() else self.idle_period)

    def step(self) -> None:
        """One probe of the holder's tab (or of a lapsed tab that may get control back)."""
        status = self.access.status()
        holder = status.holder
        client = None if holder is None else self.server.get_clients().get(holder.client_id)
        self.warning.update(client, status)
        if holder is None:
            self._probe_lapsed()
            return
        if client is None:
            self.access.revoke(f"{holder.name}'s tab is gone", holder.client_id)
            return
        if status.answered and not self.needed() and not self.warning.active:
            # Nothing moves: a frozen tab could stop nothing, and a closed one is caught by
            # on_client_disconnect. Keep the lease without a probe (each probe makes viser's
            # client redraw the 3D view); the probe resumes the moment motion needs it, and
            # its silence then counts from here, so a frozen tab still ends that motion.
            self.quiet_steps += 1
            self.access.heartbeat(holder.client_id)
            return
        budget = status.limit - status.silent_for
        if budget <= 0:
            self.access.expire_if_silent()
            self.warning.update(client, self.access.status())
            return
        if status.answered and status.silent_for < status.warn_after:
            budget = min(budget, status.warn_after - status.silent_for)  # then warn, go on
        try:
            client.local_storage.get_item("console-lease", timeout=budget)
        except TimeoutError:
            self.access.expire_if_silent()
            self.warning.update(client, self.access.status())
            return
        except RuntimeError as exc:
            if "Failed to read localStorage" not in str(exc):  # that one is an answer
                self.access.revoke(f"{holder.name}'s tab closed or lost its connection",
                                   holder.client_id)
                return
        self.probes += 1
        self.warning.update(client, self.access.status())  # how long it was silent
        self.access.heartbeat(holder.client_id)
        self.warning.update(client, self.access.status())  # heard: clears the warning

    def _probe_lapsed(self) -> None:
        """A tab whose lease lapsed while it was busy (desk mode) or still loading (any mode)
        gets control back when it answers a probe (see :meth:`AccessControl.lapsed`)."""
        cid = self.access.lapsed
        client = None if cid is None else self.server.get_clients().get(cid)
        if client is None:
            return
        try:
            client.local_storage.get_item("console-lease", timeout=self.access.lease_s)
        except TimeoutError:
            return
        except RuntimeError as exc:
            if "Failed to read localStorage" not in str(exc):
                return
        self.access.regrant(cid)
