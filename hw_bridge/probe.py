"""Link probe for commissioning: streams HELLO + DEMANDs at 100 Hz without arming, prints stats.

``python -m hw_bridge.probe --port PATH --seconds S [--baud B] [--json]`` prints
``{"sent": n, "received": n, "lost": n, "crc_errors": n, "rtt_ms": {"p50": x, "p99": y}}``
(plus a few extra keys). Definitions (see :mod:`hw_bridge.link`): ``sent`` DEMAND frames
written; ``received`` valid STATE frames; ``lost`` DEMANDs whose seq was never echoed in a
STATE's ``ack_seq`` (after a 100 ms drain); ``crc_errors`` host-side CRC failures; ``rtt_ms``
from writing a DEMAND to decoding the STATE that echoes its seq. The device is never armed,
so demands (the device's own reported positions) move nothing.

This module is the command line; the probe itself is :func:`hw_bridge.link_probe.run_probe`.
"""

from __future__ import annotations

import argparse
import json
import sys

from hw_bridge.link_probe import run_probe
from hw_bridge.transport import TransportError


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
