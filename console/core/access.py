"""Control lock for a shared console: one operator, many viewers, a lease that a dead tab loses.

Every browser starts as a viewer. ``take(client, token)`` makes it the operator (the token is
printed by ``serve.py``; ``token=None`` is a closed lab where none is needed); only the operator
may move the arm. Panels never check roles themselves: they call :meth:`AccessControl.check`
(or wrap their callbacks in ``console.panels.common.base.operator_only``), which raises
:class:`NotOperator` carrying the sentence to show the refused user.

The lock is a lease. ``console.lease.LeaseMonitor`` (the viser side) keeps it alive by a small GUI
round trip to the operator's tab every second while the arm moves, every 0.1 s while a jog
runs, none on a still console (a localStorage read: the browser's JavaScript must answer, so a
frozen or throttled tab fails it as well as a closed one or a dropped network) and revokes it
when the tab disconnects or has not answered for ``lease_s`` s; from ``warn_s`` s of silence the
operator sees a warning (:meth:`status`). Every change of holder is reported to the listeners
(the app stops the arm when an operator goes away, see
``console.core.console_core.ConsoleCore.stop_motion``).

The limits come from measurements of headless Chromium with software rendering
(``benchmarks/lease_gaps.py``, see ``console.core.lease_limits``): the gaps between a tab's answers
and the time from connect to its first answer, loaded and unloaded, desktop and throttled tablet.
"""

from __future__ import annotations

import dataclasses
import hmac
import logging
import re
import threading
import time
from typing import Any, Callable

from console.core.lease_limits import FIRST_ANSWER_S, LEASE_S, WARN_S, LeaseStatus
from console.core.operator import Operator

log = logging.getLogger(__name__)

NAME_MAX = 32
_NAME_OK = re.compile(r"[^\w .@'()-]+", re.UNICODE)


class NotOperator(PermissionError):
    """An action that needs control was attempted without it; ``reason`` says why, for users."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


# listener(new holder, previous holder, reason: a sentence naming who did what)
Listener = Callable[["Operator | None", "Operator | None", str], None]


def client_id_of(client: Any) -> int | None:
    """``client`` as an id: a viser ``ClientHandle``, an int, or None (the server itself)."""
    if client is None:
        return None
    if isinstance(client, int):
        return client
    return int(client.client_id)


def clean_name(name: str, client_id: int) -> str:
    """A display name: printable, at most :data:`NAME_MAX` characters, never empty."""
    text = _NAME_OK.sub("", str(name)).strip()[:NAME_MAX]
    return text or f"client {client_id}"


class AccessControl:
    """The single operator lock (thread-safe; no viser, so it is testable without a browser).

    Args:
        token: Secret a client must present to take control; None needs none (closed lab).
        lease_s: A holder silent for longer than this loses control (see ``console.lease.LeaseMonitor``).
        warn_s: From this much silence on the operator is warned (:meth:`status`); None:
            :data:`WARN_S`, or half of ``lease_s`` if that is smaller.
        first_answer_s: ... except before their tab has answered at all: a page still loading
            gets this long for its first answer, then ``lease_s`` applies. A tab that runs out
            of it loses control (the arm stops), but that does not count as a lost lease: it
            gets control back when it answers (:attr:`lapsed`), in desk and lab mode alike.
        first_client_takes_control: Desk mode: a client that connects while nobody holds
            control gets it without a token (only for a console bound to the loopback address).
        max_failures: Wrong tokens accepted per ``failure_window`` s from one client before
            its further attempts are refused outright, to make guessing slow. Counted per
            client and per remote address (``address_failures``), never for all clients
            together: one viewer typing wrong tokens must not keep the operator out.
        address_failures: Wrong tokens accepted per ``failure_window`` s from one address
            (all its tabs and reconnections together).
        clock: Monotonic time source (tests pass a fake one).
    """

    def __init__(self, token: str | None = None, *, lease_s: float = LEASE_S,
                 warn_s: float | None = None, first_answer_s: float = FIRST_ANSWER_S,
                 first_client_takes_control: bool = False, max_failures: int = 5,
                 failure_window: float = 10.0, address_failures: int = 20,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if token is not None and not token:
            raise ValueError("token must be a non-empty string or None")
        if lease_s <= 0:
            raise ValueError(f"lease_s must be > 0, got {lease_s}")
        if first_answer_s < lease_s:
            raise ValueError(f"first_answer_s must be >= lease_s, got {first_answer_s}")
        if warn_s is None:
            warn_s = min(WARN_S, lease_s / 2)
        if not 0 < warn_s < lease_s:
            raise ValueError(f"warn_s must be in (0, lease_s={lease_s:g}), got {warn_s}")
        self.token = token
        self.lease_s = lease_s
        self.warn_s = warn_s
        self.first_answer_s = first_answer_s
        self.first_client_takes_control = first_client_takes_control
        self.max_failures = max_failures
        self.address_failures = address_failures
        self.failure_window = failure_window
        self._clock = clock
        self._lock = threading.RLock()
        self._holder: Operator | None = None
        self._last_seen = 0.0
        self._answered = False  # has the holder's tab answered a probe yet?
        self._lapsed: int | None = None  # whose lease lapsed by silence (see lapsed)
        self._lapsed_loading = False  # ... before their tab ever answered
        self._names: dict[int, str] = {}
        self._failures: dict[object, list[float]] = {}  # per client id and per ("addr", host)
        self._listeners: list[Listener] = []

    # -- queries -----------------------------------------------------------------------------

    @property
    def holder(self) -> Operator | None:
        """The current operator, or None."""
        with self._lock:
            return self._holder

    @property
    def needs_token(self) -> bool:
        return self.token is not None

    def is_operator(self, client: Any) -> bool:
        """Whether ``client`` (handle or id) holds control now."""
        cid = client_id_of(client)
        with self._lock:
            return cid is not None and self._holder is not None and self._holder.client_id == cid

    def name_of(self, client: Any) -> str:
        """The name ``client`` gave (or ``client N``); "server" for None."""
        cid = client_id_of(client)
        if cid is None:
            return "server"
        with self._lock:
            return self._names.get(cid, f"client {cid}")

    def set_name(self, client: Any, name: str) -> str:
        """Record the name ``client`` gave; returns the cleaned name."""
        cid = client_id_of(client)
        if cid is None:
            raise ValueError("the server has no name to set")
        cleaned = clean_name(name, cid)
        with self._lock:
            self._names[cid] = cleaned
            if self._holder is not None and self._holder.client_id == cid:
                self._holder = dataclasses.replace(self._holder, name=cleaned)
        return cleaned

    def refusal(self, action: str) -> str:
        """The sentence a viewer sees when ``action`` (e.g. "jog") is refused."""
        holder = self.holder
        how = "take control with the token" if self.needs_token else "take control"
        if holder is None:
            return (f"Only the operator can {action} — nobody holds control; {how} "
                    "(Session panel).")
        return (f"Only the operator can {action} — {holder.name} holds control; ask them or "
                f"{how} (Session panel).")

    def viewer_note(self) -> str:
        """The line atop a viewer's page: who operates and how to get control (plain text)."""
        holder = self.holder
        how = ("press Take control in the Session tab with the operator token (printed where "
               "serve.py runs)" if self.needs_token else "press Take control in the Session tab")
        if holder is None:
            return f"You are viewing: nobody operates. To operate, {how}."
        return (f"You are viewing: {holder.name} operates. To operate, ask {holder.name}, "
                f"then {how}.")

    def check(self, client: Any, action: str = "do that") -> None:
        """Allow ``action`` for ``client`` only if it holds control.

        ``client`` None means the server itself (programmatic calls), which is always allowed.

        Raises:
            NotOperator: with the reason to show the user.
        """
        if client is None or self.is_operator(client):
            return
        raise NotOperator(self.refusal(action))

    # -- changes -----------------------------------------------------------------------------

    def add_listener(self, fn: Listener) -> None:
        """Call ``fn(new, previous, reason)`` after every change of holder (outside the lock)."""
        with self._lock:
            self._listeners.append(fn)

    def _notify(self, new: Operator | None, previous: Operator | None, reason: str) -> None:
        for fn in list(self._listeners):
            try:
                fn(new, previous, reason)
            except Exception:  # one broken listener must not keep the others from stopping
                log.exception("access listener failed")

    def _recent_failures(self, key: object, now: float) -> list[float]:
        times = [t for t in self._failures.get(key, ()) if now - t < self.failure_window]
        if times:
            self._failures[key] = times
        else:
            self._failures.pop(key, None)
        return times

    def take(self, client: Any, token: str | None = None, name: str | None = None,
             address: str | None = None) -> Operator:
        """Make ``client`` the operator (taking over from any other holder).

        ``address`` is the browser's remote host, if known: wrong tokens are limited per client
        and per address.

        Raises:
            NotOperator: wrong or missing token, or too many wrong tokens recently from this
                client or its address.
        """
        cid = client_id_of(client)
        if cid is None:
            raise ValueError("the server cannot take control")
        now = self._clock()
        with self._lock:
            if self.token is not None:
                keys: list[tuple[object, int]] = [(cid, self.max_failures)]
                if address is not None:
                    keys.append((("addr", address), self.address_failures))
                if any(len(self._recent_failures(k, now)) >= limit for k, limit in keys):
                    raise NotOperator("Too many wrong tokens in the last "
                                      f"{self.failure_window:.0f} s; wait and try again.")
                given = (token or "").strip()
                if not hmac.compare_digest(given.encode(), self.token.encode()):
                    for k, _ in keys:
                        self._failures.setdefault(k, []).append(now)
                    if len(self._failures) > 10_000:  # bounded: forget the oldest keys
                        for k in list(self._failures)[:5_000]:
                            self._failures.pop(k, None)
                    raise NotOperator("Wrong operator token: copy it from the terminal "
                                      "where serve.py runs.")
            if name is not None:
                self._names[cid] = clean_name(name, cid)
            previous = self._holder
            if previous is not None and previous.client_id == cid:
                self._last_seen = now
                return previous
            self._holder = Operator(cid, self._names.get(cid, f"client {cid}"), time.time())
            self._last_seen = now
            self._answered = False
            self._lapsed = None
            self._lapsed_loading = False
            new = self._holder
        reason = (f"{new.name} took control" if previous is None
                  else f"{new.name} took control from {previous.name}")
        self._notify(new, previous, reason)
        return new

    def grant_if_free(self, client: Any) -> Operator | None:
        """Desk mode: give control to ``client`` if nobody holds it (no token needed)."""
        cid = client_id_of(client)
        with self._lock:
            if not self.first_client_takes_control or self._holder is not None or cid is None:
                return None
            self._holder = Operator(cid, self._names.get(cid, f"client {cid}"), time.time())
            self._last_seen = self._clock()
            self._answered = False
            self._lapsed = None
            self._lapsed_loading = False
            new = self._holder
        self._notify(new, None, f"{new.name} took control (first browser on a desk console)")
        return new

    def release(self, client: Any) -> bool:
        """Give up control if ``client`` holds it; returns whether it did."""
        cid = client_id_of(client)
        with self._lock:
            previous = self._holder
            if previous is None or previous.client_id != cid:
                return False
            self._holder = None
        self._notify(None, previous, f"{previous.name} released control")
        return True

    def revoke(self, reason: str, client: Any = None) -> Operator | None:
        """Take control away (lease lost); only from ``client`` if given. Returns who lost it."""
        cid = client_id_of(client)
        with self._lock:
            previous = self._holder
            if previous is None or (cid is not None and previous.client_id != cid):
                return None
            self._holder = None
        self._notify(None, previous, reason)
        return previous

    def forget(self, client: Any) -> None:
        """Drop what is known about a disconnected client (its name)."""
        cid = client_id_of(client)
        if cid is None:  # the server itself: nothing known about it
            return
        with self._lock:
            self._names.pop(cid, None)
            if self._lapsed == cid:
                self._lapsed = None

    # -- lease -------------------------------------------------------------------------------

    def heartbeat(self, client: Any) -> bool:
        """Record that the holder answered; False if ``client`` is not the holder."""
        cid = client_id_of(client)
        with self._lock:
            if self._holder is None or self._holder.client_id != cid:
                return False
            self._last_seen = self._clock()
            self._answered = True
            return True

    def last_heard(self, client: Any) -> float | None:
        """Clock time ``client``'s tab last answered (or took control), if it holds control."""
        cid = client_id_of(client)
        with self._lock:
            if self._holder is None or self._holder.client_id != cid:
                return None
            return self._last_seen

    def lease_limit(self) -> float:
        """How long the holder may stay silent: ``lease_s``, or ``first_answer_s`` until the
        holder's tab has answered once."""
        with self._lock:
            return self.lease_s if self._answered else self.first_answer_s

    def silent_for(self) -> float:
        """Seconds since the holder last answered (0 when nobody holds control)."""
        with self._lock:
            return 0.0 if self._holder is None else self._clock() - self._last_seen

    def status(self) -> LeaseStatus:
        """The lease now: holder, silence, limit, whether to warn (one consistent snapshot)."""
        with self._lock:
            return LeaseStatus(self._holder, self.silent_for(), self.lease_limit(), self.warn_s,
                               self._answered)

    def expire_if_silent(self) -> Operator | None:
        """Revoke the lease if the holder has been silent for ``lease_s`` (``first_answer_s``
        before their first answer); returns who lost it."""
        with self._lock:
            holder = self._holder
            limit = self.lease_limit()
            if holder is None or self._clock() - self._last_seen < limit:
                return None
            self._lapsed = holder.client_id
            self._lapsed_loading = not self._answered
            if self._answered:
                reason = f"{holder.name}'s tab went silent for {limit:g} s"
            else:
                reason = (f"{holder.name}'s tab did not answer within {limit:g} s (still "
                          "loading?); it gets control back when it answers")
        return self.revoke(reason, holder.client_id)

    @property
    def lapsed(self) -> int | None:
        """The client whose lease lapsed by silence (not by release or close) and that gets
        control back once its tab answers again: in desk mode always, in lab mode only a tab
        that never answered (a page still loading has not lost anything); None otherwise."""
        with self._lock:
            if self._holder is not None:
                return None
            if not (self.first_client_takes_control or self._lapsed_loading):
                return None
            return self._lapsed

    def regrant(self, client: Any) -> Operator | None:
        """Give control back to the :attr:`lapsed` client whose tab answered (the arm stopped
        when the lease lapsed; getting control back moves nothing)."""
        cid = client_id_of(client)
        with self._lock:
            if cid is None or cid != self.lapsed:
                return None
            self._holder = Operator(cid, self._names.get(cid, f"client {cid}"), time.time())
            self._last_seen = self._clock()
            self._answered = True
            self._lapsed = None
            self._lapsed_loading = False
            new = self._holder
        self._notify(new, None, f"{new.name} has control again (their tab answers again)")
        return new
