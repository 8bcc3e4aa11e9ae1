"""Link probe for commissioning: HELLO, then 100 Hz DEMANDs without arming; the link's figures.

:func:`run_probe` returns ``{"sent": n, "received": n, "lost": n, "crc_errors": n,
"rtt_ms": {"p50": x, "p99": y}}`` (plus a few extra keys). Definitions (see :mod:`hw_bridge.link`):
``sent`` DEMAND frames written; ``received`` valid STATE frames; ``lost`` DEMANDs whose seq was
never echoed in a STATE's ``ack_seq`` (after a 100 ms drain); ``crc_errors`` host-side CRC
failures; ``rtt_ms`` from writing a DEMAND to decoding the STATE that echoes its seq. The device
is never armed, so demands (the device's own reported positions) move nothing.

Command line: ``python -m hw_bridge.probe`` (:mod:`hw_bridge.probe`).
"""

from __future__ import annotations

import time
from typing import Any

from hw_bridge import protocol as p
from hw_bridge.link import Link
from hw_bridge.transport import open_serial


def run_probe(port: str, seconds: float, baud: int = 1_000_000, rate_hz: float = 100.0,
              hello_timeout: float = 0.5) -> dict[str, Any]:
    """Run the probe and return the statistics dict; raises TransportError / RuntimeError."""
    transport = open_serial(port, baud)
    try:
        link = Link(transport)
        link.all_rtts = []
        transport.reset_input()
        transport.write(p.DELIMITER)
        link.send(p.Hello())
        hello: p.Hello | None = None
        deadline = time.perf_counter() + hello_timeout
        while hello is None and time.perf_counter() < deadline:
            hello = next((m for m in link.poll() if isinstance(m, p.Hello)), None)
        if hello is None:
            raise RuntimeError(f"no HELLO answer from {port} within {hello_timeout * 1000:.0f} ms")
        counts = (list(link.last_state.positions) if link.last_state is not None
                  else [0] * hello.n_motors)
        period = 1.0 / rate_hz
        start = time.perf_counter()
        next_send = start
        end = start + seconds
        while True:
            now = time.perf_counter()
            if now >= next_send:
                if now >= end:
                    break
                link.send_demand(counts)
                next_send += period
                if next_send <= now:  # overrun: skip, do not catch up
                    next_send = now + period
            link.poll()
        drain_end = time.perf_counter() + 0.1
        while time.perf_counter() < drain_end:
            link.poll()
        link.finish()
    finally:
        transport.close()
    c, d = link.counters, link.decoder.stats
    return {
        "sent": c.sent, "received": c.received, "lost": c.lost, "crc_errors": d.crc_errors,
        "rtt_ms": link.rtt_percentiles_ms(link.all_rtts),
        "bad_frames": d.bad_frames, "device_rx_errors": c.device_rx_errors,
        "device": {"protocol": hello.version, "motors": hello.n_motors,
                   "watchdog_ms": hello.watchdog_ms},
    }
