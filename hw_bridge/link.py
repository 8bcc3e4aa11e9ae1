"""Host end of the framed link: sends messages, decodes replies, keeps round-trip and loss counts.

Used by :class:`hw_bridge.interface.SerialHardware` and by the link probe. Definitions:

* **rtt**: time from writing DEMAND ``seq`` to decoding the first STATE with ``ack_seq == seq``.
* **lost**: DEMANDs whose seq was never echoed (the DEMAND or its STATE was lost, or the
  device coalesced it); a seq is declared lost once a newer seq has been echoed, or by
  :meth:`Link.finish` for those still pending.
"""

from __future__ import annotations

import collections
import dataclasses
import threading
import time
from typing import Callable

import numpy as np

from hw_bridge import protocol as p
from hw_bridge.transport import Transport

_RTT_WINDOW = 1000
_PENDING_MAX = 512


@dataclasses.dataclass
class LinkCounters:
    """Cumulative link statistics."""

    sent: int = 0
    received: int = 0
    acked: int = 0
    lost: int = 0
    device_rx_errors: int = 0


class Link:
    """Framing, sequencing and statistics on top of a :class:`Transport`.

    Args:
        transport: Open byte pipe.
        clock: Monotonic clock in seconds (injectable for tests).
        rtt_window: How many recent round trips the percentiles cover.
    """

    def __init__(self, transport: Transport, clock: Callable[[], float] = time.perf_counter,
                 rtt_window: int = _RTT_WINDOW):
        self.transport = transport
        self.clock = clock
        self.decoder = p.StreamDecoder()
        self.counters = LinkCounters()
        self.rtts: collections.deque[float] = collections.deque(maxlen=rtt_window)
        self.all_rtts: list[float] | None = None  # set to [] to keep every sample (probe)
        self.seq = 0
        self.last_state: p.State | None = None
        self.last_state_time: float | None = None
        self._pending: collections.OrderedDict[int, float] = collections.OrderedDict()
        self._lock = threading.Lock()  # a receive thread and the control thread share the link

    def send(self, msg: p.Message) -> None:
        """Encode and write one message (TransportError propagates)."""
        self.transport.write(p.encode(msg))

    def send_demand(self, counts: "list[int] | tuple[int, ...] | np.ndarray",
                    mask: int | None = None) -> int:
        """Send the next DEMAND (never a retransmission); returns its seq."""
        self.seq = (self.seq + 1) & 0xFFFFFFFF or 1
        values = tuple(int(c) for c in counts)
        msg = (p.Demand.full(self.seq, values) if mask is None
               else p.Demand(self.seq, mask, values))
        data = p.encode(msg)
        with self._lock:
            self._pending[self.seq] = self.clock()
            while len(self._pending) > _PENDING_MAX:
                self._pending.popitem(last=False)
                self.counters.lost += 1
        self.transport.write(data)
        self.counters.sent += 1
        return self.seq

    def reset_sequence(self) -> None:
        """Start over at seq 1 (after HELLO/ARM the device accepts any seq); pending are dropped."""
        with self._lock:
            self.seq = 0
            self._pending.clear()

    def poll(self) -> list[p.Message]:
        """Read what is waiting (or wait the transport's short read timeout) and decode it."""
        chunk = self.transport.read_chunk()
        return self.feed(chunk, self.clock()) if chunk else []

    def feed(self, chunk: bytes, now: float) -> list[p.Message]:
        """Decode bytes received at ``now`` and update statistics."""
        msgs = self.decoder.feed(chunk)
        for m in msgs:
            if isinstance(m, p.State):
                with self._lock:
                    self._on_state(m, now)
        return msgs

    def _on_state(self, m: p.State, now: float) -> None:
        self.counters.received += 1
        self.counters.device_rx_errors = m.rx_errors
        self.last_state, self.last_state_time = m, now
        sent_at = self._pending.get(m.ack_seq)
        if sent_at is None:
            return
        self.rtts.append(now - sent_at)
        if self.all_rtts is not None:
            self.all_rtts.append(now - sent_at)
        self.counters.acked += 1
        # everything older than the echoed seq can no longer be echoed: lost
        while self._pending:
            seq, _ = next(iter(self._pending.items()))
            self._pending.popitem(last=False)
            if seq == m.ack_seq:
                break
            self.counters.lost += 1

    def finish(self) -> None:
        """Count every still-unechoed DEMAND as lost (call after a final drain)."""
        with self._lock:
            self.counters.lost += len(self._pending)
            self._pending.clear()

    def rtt_percentiles_ms(self, samples: "list[float] | None" = None) -> dict[str, float | None]:
        """p50/p99 of the round trips in ms (None without samples)."""
        with self._lock:
            data = list(self.rtts) if samples is None else list(samples)
        if not data:
            return {"p50": None, "p99": None}
        a = np.asarray(data) * 1000.0
        return {"p50": round(float(np.percentile(a, 50)), 3),
                "p99": round(float(np.percentile(a, 99)), 3)}
