"""Link probe for commissioning: streams HELLO + DEMANDs at 100 Hz without arming, prints stats.

``python -m hw_bridge.probe --port PATH --seconds S [--baud B] [--json]`` prints
``{"sent": n, "received": n, "lost": n, "crc_errors": n, "rtt_ms": {"p50": x, "p99": y}}``
(plus a few extra keys). Definitions (see :mod:`hw_bridge.link`): ``sent`` DEMAND frames
written; ``received`` valid STATE frames; ``lost`` DEMANDs whose seq was never echoed in a
STATE's ``ack_seq`` (after a 100 ms drain); ``crc_errors`` host-side CRC failures; ``rtt_ms``
from writing a DEMAND to decoding the STATE that echoes its seq. The device is never armed,
so demands (the device's own reported positions) move nothing.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

from hw_bridge import protocol as p
from hw_bridge.link import Link
from hw_bridge.transport import TransportError, open_serial


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


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m hw_bridge.probe", description=__doc__.split("\n")[0])
    ap.add_argument("--port", required=True, help="device path or pyserial URL")
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--baud", type=int, default=1_000_000)
    ap.add_argument("--json", action="store_true", help="print one JSON object only")
    args = ap.parse_args(argv)
    if not args.seconds > 0:
        ap.error("--seconds must be > 0")
    try:
        stats = run_probe(args.port, args.seconds, args.baud)
    except (TransportError, RuntimeError) as exc:
        print(f"probe: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(stats))
    else:
        r = stats["rtt_ms"]
        print(f"port {args.port}: device protocol v{stats['device']['protocol']}, "
              f"{stats['device']['motors']} motors, watchdog {stats['device']['watchdog_ms']} ms")
        print(f"sent {stats['sent']}  received {stats['received']}  lost {stats['lost']}  "
              f"crc errors {stats['crc_errors']}  (device rx errors {stats['device_rx_errors']})")
        print(f"round trip p50 {r['p50']} ms  p99 {r['p99']} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
