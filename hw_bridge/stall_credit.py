"""The host's own stalls, counted apart so a late read() is not taken for a silent device.

:class:`OwnStall` is what :meth:`hw_bridge.interface.SerialHardware.read` subtracts from the
age of the last STATE before it calls the link lost.
"""

from __future__ import annotations


class OwnStall:
    """How much of the time since the last STATE this host could not listen, s.

    :meth:`credit` runs once a period (each ``read``); when calls are further apart the loop's
    CPU was taken (35-60 ms measured on the 2-core VM: benchmarks/link_gaps.py), the receive
    thread could not decode and the emulator on that CPU could not send. That part beyond one
    period of each late read is credited: the link is lost after ``state_timeout_s`` of
    silence while this host listened (a punctual host: the 40 ms rule unchanged). The device's
    watchdog still acts on the DEMANDs a stalled host did not send.

    Args:
        period_s: The loop's period (a read later than half a period more is a stall).
    """

    def __init__(self, period_s: float) -> None:
        self.period_s = period_s
        self.reset()

    def reset(self) -> None:
        """Forget every stall (a new connection)."""
        self._last_read: float | None = None   # when credit() last ran
        self._since: float | None = None       # the STATE time the count belongs to
        self._stalled_s = 0.0

    def credit(self, now: float, last_state: float | None) -> float:
        """The stall since the STATE received at ``last_state``, with a read at ``now``."""
        prev, self._last_read = self._last_read, now
        if last_state != self._since:  # a newer STATE: the count starts again
            self._since, self._stalled_s = last_state, 0.0
        if prev is not None and last_state is not None:
            late = now - max(prev, last_state) - self.period_s
            if late > self.period_s / 2:  # (ordinary jitter is not a stall)
                self._stalled_s += late
        return self._stalled_s
