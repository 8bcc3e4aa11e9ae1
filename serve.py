"""Entry point: serve the operator console for one robot until Ctrl-C.

    .venv/bin/python serve.py --robot soft-arm --host 127.0.0.1 --port 8080

``--hardware emulator|mock`` and ``--port-path`` are accepted for the serial bridge; until the
bridge lands they are only reported and the console runs the kinematic simulation.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading

from console.app import ConsoleApp
from core.robots import RobotFileError, available, load


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Command-line options."""
    p = argparse.ArgumentParser(description="Browser operator console for the soft and "
                                            "extensible arms (viser).")
    p.add_argument("--robot", default="soft-arm",
                   help=f"robot name ({', '.join(available())}) or path to a robot .toml")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to bind (default 127.0.0.1; use 0.0.0.0 to serve the lab)")
    p.add_argument("--port", type=int, default=8080, help="HTTP/websocket port (default 8080)")
    p.add_argument("--hardware", choices=("emulator", "mock"), default=None,
                   help="hardware bridge to attach (not available yet: noted and ignored)")
    p.add_argument("--port-path", default=None, help="serial device for --hardware")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Build the console and serve it until SIGINT/SIGTERM."""
    args = parse_args(argv)
    try:
        robot = load(args.robot)
    except RobotFileError as exc:
        print(f"serve.py: {exc}", file=sys.stderr)
        return 2
    if not 0 < args.port < 65536:
        print(f"serve.py: --port must be in 1..65535, got {args.port}", file=sys.stderr)
        return 2
    status = "Kinematic simulation (no hardware connected)"
    if args.hardware is not None:
        where = f" on {args.port_path}" if args.port_path else ""
        status = (f"Hardware '{args.hardware}'{where} requested, but the bridge is not "
                  "available yet: kinematic simulation")
        print(f"serve.py: {status}", file=sys.stderr)

    import viser  # after argument checks, so --help and bad input stay fast

    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    server = viser.ViserServer(host=args.host, port=args.port, verbose=False)
    app = ConsoleApp(robot, server, status=status).start()
    shown = "127.0.0.1" if args.host in ("0.0.0.0", "") else args.host
    print(f"Console for '{robot.name}' at http://{shown}:{args.port}/  (Ctrl-C to stop)",
          flush=True)
    try:
        while not done.wait(0.5):
            pass
    except KeyboardInterrupt:
        pass
    finally:
        app.stop()
        server.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
