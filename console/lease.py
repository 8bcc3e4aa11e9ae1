"""The operator lease's heartbeat: probe the operator's tab, revoke control when it goes silent.

:class:`LeaseMonitor` is the viser side of ``console.access.AccessControl``: it needs a live
server and its clients, while the lock itself stays testable without a browser.
"""

from __future__ import annotations

import threading

import viser

from console.access import AccessControl


class LeaseMonitor:
    """Keeps the operator's lease alive by probing their tab; revokes it on silence or close.

    A thread probes the holder's tab every ``probe_period`` s with a localStorage read (a
    JavaScript round trip) bounded so that the lease expires at most ``lease_s`` after the last
    answer; the answers are also the heartbeats that keep a set-point jog moving (it holds when
    the last one is over 300 ms old, see ``console.hold_to_run``), hence the 0.1 s default; a closed tab is also caught at once by ``server.on_client_disconnect``. On a desk
    console (``first_client_takes_control``) a tab whose lease lapsed by silence -- a software-
    rendered page busy for seconds -- is probed too and gets control back when it answers (the
    arm stopped when the lease lapsed and stays stopped).
    """

    def __init__(self, server: viser.ViserServer, access: AccessControl,
                 probe_period: float = 0.1) -> None:
        self.server = server
        self.access = access
        self.probe_period = probe_period
        self.probes = 0
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
        while not self._stop.wait(self.probe_period):
            holder = self.access.holder
            if holder is None:
                self._probe_lapsed()
                continue
            client = self.server.get_clients().get(holder.client_id)
            if client is None:
                self.access.revoke(f"{holder.name}'s tab is gone", holder.client_id)
                continue
            budget = self.access.lease_limit() - self.access.silent_for()
            if budget <= 0:
                self.access.expire_if_silent()
                continue
            try:
                client.local_storage.get_item("console-lease", timeout=budget)
            except TimeoutError:
                self.access.expire_if_silent()
                continue
            except RuntimeError as exc:
                if "Failed to read localStorage" not in str(exc):  # that one is an answer
                    self.access.revoke(f"{holder.name}'s tab closed or lost its connection",
                                       holder.client_id)
                    continue
            self.probes += 1
            self.access.heartbeat(holder.client_id)

    def _probe_lapsed(self) -> None:
        """Desk mode: a tab whose lease lapsed while it was busy gets control back when it
        answers a probe again (see :meth:`AccessControl.regrant`)."""
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
