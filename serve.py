"""Entry point: serve the operator console for one robot until Ctrl-C.

    .venv/bin/python serve.py --robot soft-arm                    # this machine only (desk)
    .venv/bin/python serve.py --robot soft-arm --host 0.0.0.0     # the lab network

Network: ``--host`` is the address to bind (default 127.0.0.1: only this machine can connect;
``0.0.0.0`` serves every interface and prints the URL(s) to open from other machines) and
``--port`` the HTTP/websocket port: if it is busy serve.py exits 2 (``--next-free-port``: take
the next free one and say so). viser's share tunnel is off (button hidden, request
ignored). Control: every browser starts as a viewer; "Take control" in the Session panel needs
the operator token printed here (``--no-token`` for a closed lab). On a loopback-only console
(a single desk) the first browser gets control without the token unless ``--lab`` is given.
Files: recordings and exports are written only under ``--data-dir`` (default ``./runs``).
viser: ``console.web.install()`` patches viser's internals before any server exists; on a viser
other than the tested one serve.py says so and exits 2 (``--allow-untested-viser``: warn, go on).

Hardware: ``--hardware emulator`` (default) starts the device emulator on a pseudo-terminal, so
the demo runs through the real serial stack; ``--hardware mock`` keeps the device in-process;
``--port-path PATH`` talks to a real controller (see ``console.core.hardware_setup``). The Hardware
panel (both robots) picks the port, connects, arms the device and shows the link's health.

Lifecycle (``console.serve_lifecycle``): SIGTERM / Ctrl-C while starting exit at once; once
serving they shut down in order within 2 s. Every child process ends within 1 s of this one's
death by any signal (``hw_bridge.parent_watch``); the device emulator logs its watchdog's trip
to the terminal and ``<data-dir>/device-events.jsonl``, and the next start reports it.
"""

from __future__ import annotations

import argparse
import html
import ipaddress
import os
import secrets
import socket
import sys
import traceback
import warnings
from pathlib import Path
from typing import Any

from console import web
from console.core.access import AccessControl
from console.app import ConsoleApp
from console.panel_sets import DEFAULT_PANELS
from console.core.model import model_for
from console.serve_lifecycle import Lifecycle, port_in_use
from console.web.connection_gate import ConnectionLimits
from console.web.connection_gate import is_loopback as address_is_loopback
from console.core.services import ConsoleServices
from console.core.state import StateStore
from core.robots import RobotFileError, available, load


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Command-line options."""
    p = argparse.ArgumentParser(description="Browser operator console for the soft and "
                                            "extensible arms (viser).")
    p.add_argument("--robot", default="soft-arm",
                   help=f"robot name ({', '.join(available())}) or path to a robot .toml")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to bind (default 127.0.0.1: this machine only; 0.0.0.0 serves "
                        "the lab network and prints the URLs to open)")
    p.add_argument("--port", type=int, default=8080,
                   help="HTTP/websocket port (default 8080); if it is busy serve.py exits 2")
    p.add_argument("--next-free-port", action="store_true",
                   help="if --port is busy, serve on the next free port (printed) instead")
    p.add_argument("--data-dir", default="runs",
                   help="the only folder the console reads or writes (recordings, exports); "
                        "default ./runs")
    p.add_argument("--no-token", action="store_true",
                   help="closed lab: 'Take control' needs no operator token")
    p.add_argument("--lab", action="store_true",
                   help="every browser starts as a viewer even on 127.0.0.1 (the default for "
                        "any other --host)")
    p.add_argument("--demo", action="store_true",
                   help="add a 'Run demo motion' button (operator only) for demos and tests")
    p.add_argument("--hardware", choices=("emulator", "mock"), default="emulator",
                   help="emulator (default): the device emulator on a pseudo-terminal, through "
                        "the real serial stack; mock: an in-process device, no serial")
    p.add_argument("--port-path", default=None,
                   help="serial device or pyserial URL of a real controller (overrides "
                        "--hardware)")
    p.add_argument("--rt-cpu", choices=("auto", "none"), default="auto",
                   help="auto: keep the highest CPU for the arm's 100 Hz loop process and its "
                        "device emulator, the console and planner on the others; none: no "
                        "pinning")
    p.add_argument("--foxglove-port", type=int, default=None, metavar="P",
                   help="also stream the lab channels live over the Foxglove WebSocket protocol "
                        "on port P, bound like --host (off by default; read-only)")
    p.add_argument("--allow-untested-viser", action="store_true",
                   help="patch and serve on a viser other than the tested "
                        f"{web.TESTED_VISER_VERSION} (a loud warning instead of exit 2)")
    p.add_argument("--slip", type=float, default=None, metavar="F",
                   help="extensible arm on the emulator: its racks slip on their pinions by F "
                        "(0..0.5) of each move's travel, and it streams a noisy tip measurement "
                        "(Repeatability: open vs closed loop on the tip); off by default")
    p.add_argument("--max-connections", type=int, default=ConnectionLimits.total, metavar="N",
                   help="websocket connections served at once in all (default "
                        f"{ConnectionLimits.total}); this machine's and the operator's address "
                        "are never refused")
    p.add_argument("--max-connections-per-address", type=int,
                   default=ConnectionLimits.per_address, metavar="N",
                   help="websocket connections served at once from one address (default "
                        f"{ConnectionLimits.per_address})")
    args = p.parse_args(argv)
    if args.max_connections < 1 or args.max_connections_per_address < 1:
        p.error("--max-connections and --max-connections-per-address must be at least 1")
    if args.slip is not None and not 0.0 <= args.slip <= 0.5:
        p.error("--slip must be in [0, 0.5]")
    return args


def is_loopback(host: str) -> bool:
    """Whether binding ``host`` serves this machine only (``localhost``, or a loopback address
    as the connection gate reads a browser's: ``console.web.connection_gate.is_loopback``)."""
    return host == "localhost" or address_is_loopback(host)


def lan_addresses() -> list[str]:
    """This machine's non-loopback IPv4 addresses (best effort, no packets sent)."""
    found: list[str] = []
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.connect(("192.0.2.1", 9))  # TEST-NET-1: picks the outgoing interface, sends nothing
            found.append(s.getsockname()[0])
    except OSError:
        pass
    try:
        for info in socket.getaddrinfo(socket.gethostname(), None, socket.AF_INET):
            found.append(str(info[4][0]))
    except OSError:
        pass
    out = []
    for a in found:
        if a not in out and not ipaddress.ip_address(a).is_loopback:
            out.append(a)
    return out


def urls(host: str, port: int) -> list[str]:
    """The URL(s) to open for a console bound to ``host``."""
    if host in ("0.0.0.0", "", "::"):
        return [f"http://127.0.0.1:{port}/"] + [f"http://{a}:{port}/" for a in lan_addresses()]
    shown = f"[{host}]" if ":" in host else host
    return [f"http://{shown}:{port}/"]


def cpu_partition(args: argparse.Namespace) -> Any:
    """The CPU split ``--rt-cpu`` asks for (:mod:`hw_bridge.cpu_partition`; None: no pinning)."""
    from hw_bridge.cpu_partition import CpuPartition
    return CpuPartition.default() if getattr(args, "rt_cpu", "auto") == "auto" else None


def pin_console(services: ConsoleServices) -> str:
    """Move this (console) process off the real-time CPU; returns what was done, for the log."""
    from hw_bridge.cpu_partition import pin_process
    part = services.cpu_partition
    if part is None:
        return "CPUs: no pinning"
    pin_process(part.other)
    return f"CPUs: {part.describe()}"


def install_viser_patches(args: argparse.Namespace) -> int | None:
    """``console.web.install()``: None when viser is patched, 2 (after one line naming both
    versions) when it is not the tested viser and ``--allow-untested-viser`` was not given."""
    allow = getattr(args, "allow_untested_viser", False)
    try:
        report = web.install(allow_untested=allow)
    except web.UntestedViser as exc:
        print(f"serve.py: viser {exc.found} is installed, the console is tested on viser "
              f"{exc.tested}: install viser=={exc.tested} or give --allow-untested-viser",
              file=sys.stderr)
        return 2
    if not report.tested:
        print(f"serve.py: WARNING: UNTESTED VISER {report.viser_version} (tested: "
              f"{web.TESTED_VISER_VERSION}); its internals are patched anyway "
              "(--allow-untested-viser)", file=sys.stderr, flush=True)
    return None


def build(args: argparse.Namespace, robot: Any, status: str) -> tuple[Any, ConsoleApp, str | None]:
    """Patch viser (``console.web.install``, idempotent), create the viser server and the
    console app; returns (server, app, token)."""
    import viser  # after argument checks, so --help and bad input stay fast

    web.install(allow_untested=getattr(args, "allow_untested_viser", False))  # before the server

    from console.core import hardware_setup
    from console.core.demo_motion import DemoMotion
    from console.panels.soft_arm.capture import CapturePanel
    from console.panels.soft_arm.control import ControlPanel
    from console.panels.common.design_study import DesignStudyPanel
    from console.panels.extensible.panel_set import EXTENSIBLE_PANELS
    from console.panels.common.hardware import HardwarePanel
    from console.panels.soft_arm.panel_set import grasp_panels
    from console.panels.common.session import SessionPanel
    from console.panels.soft_arm.trials import TrialsPanel
    from console.panels.common.view import ViewPanel

    token = None if args.no_token else secrets.token_urlsafe(9)
    desk = is_loopback(args.host) and not args.lab
    access = AccessControl(token, first_client_takes_control=desk)
    server = viser.ViserServer(host=args.host, port=args.port, verbose=False)
    mode = getattr(args, "hardware", "mock")
    port_path = getattr(args, "port_path", None)
    store = StateStore(model_for(robot),
                       mirror_commands=hardware_setup.mirrors_commands(robot, mode, port_path))
    cpus = cpu_partition(args)  # either arm's loop process (and emulator) on the real-time CPU
    device_log: list[str] = []
    if mode == "emulator" and not port_path:  # what the emulator logged after the last start
        device_log = hardware_setup.report_device_log(Path(args.data_dir))
    services = hardware_setup.attach(robot, store, mode, port_path, cpus=cpus,
                                     slip=getattr(args, "slip", None))
    if args.demo:
        services = services.replace(demo=DemoMotion(store))
    limits = ConnectionLimits(per_address=getattr(args, "max_connections_per_address",
                                                  ConnectionLimits.per_address),
                              total=getattr(args, "max_connections", ConnectionLimits.total))
    app = ConsoleApp(robot, server, status=status, access=access, data_dir=Path(args.data_dir),
                     panels=(), store=store, services=services, connection_limits=limits)
    if device_log:
        app.status.content += ("<br><small><b>Device log:</b> " + html.escape(device_log[-1])
                               + "</small>")
    for panel_cls in (*DEFAULT_PANELS, *grasp_panels(), ControlPanel, CapturePanel, TrialsPanel,
                      *EXTENSIBLE_PANELS, DesignStudyPanel, HardwarePanel, SessionPanel,
                      ViewPanel):
        app.add_panel(panel_cls)
    return server, app, token


def main(argv: list[str] | None = None) -> int:
    """Build the console and serve it until SIGINT/SIGTERM."""
    args = parse_args(argv)
    # viser warns about every message queued for a browser that already left ("Queued a ... on
    # a closed connection"): widgets being built for a browser that leaves meanwhile print a
    # line each, so browsers coming and going (a lab's tabs, a flood) fill the terminal. The
    # console drops such a browser's state on its disconnect (console.panels.common.events
    # .connected; tests/console/test_connection_flood.py): the lines tell nobody anything.
    warnings.filterwarnings("ignore", message=r"Queued a \w+ on a closed connection",
                            category=UserWarning)
    refused = install_viser_patches(args)  # before any server: the client guard, shared sends
    if refused is not None:
        return refused
    try:
        robot = load(args.robot)
    except RobotFileError as exc:
        print(f"serve.py: {exc}", file=sys.stderr)
        return 2
    for flag, value in (("--port", args.port), ("--foxglove-port", args.foxglove_port)):
        if value is not None and not 0 < value < 65536:
            print(f"serve.py: {flag} must be in 1..65535, got {value}", file=sys.stderr)
            return 2
    try:
        Path(args.data_dir).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        print(f"serve.py: --data-dir {args.data_dir}: {exc}", file=sys.stderr)
        return 2
    if args.slip is not None and (robot.kind != "delta" or args.hardware != "emulator"
                                  or args.port_path):
        print("serve.py: --slip needs the extensible arm on the device emulator",
              file=sys.stderr)
        return 2
    # A signal from now on, while starting: exit at once (installed before the hardware line,
    # which is what a supervisor or test reads as "starting").
    life = Lifecycle().install()
    from console.core.hardware_setup import describe
    status = describe(robot, args.hardware, args.port_path)
    print(f"serve.py: hardware: {status}", file=sys.stderr)

    busy = port_in_use(args.host, args.port)
    if busy and not args.next_free_port:
        print(f"serve.py: {busy}; choose another with --port, or give --next-free-port",
              file=sys.stderr)
        return 2
    fox_busy = (port_in_use(args.host, args.foxglove_port)
                 if args.foxglove_port is not None else None)
    if fox_busy:  # said before anything serves, like the page's port
        print(f"serve.py: --foxglove-port: {fox_busy}; choose another", file=sys.stderr)
        return 2
    try:
        server, app, token = build(args, robot, status)
    except Exception as exc:  # noqa: BLE001 - say why, plainly, and leave no children behind
        traceback.print_exc()
        print(f"serve.py: start-up failed: {exc}", file=sys.stderr, flush=True)
        sys.stdout.flush()
        os._exit(1)  # (not a normal exit: that would wait for a half-started control process)
    # The Foxglove port opens right after the console is built, before it starts drawing and
    # before its address is printed (not before the page's port: viser serves from its
    # constructor, and the bridge taps the recorder the console builds with that server).
    bridge = None
    if args.foxglove_port is not None:  # Foxglove / Lichtblick: "Open connection" -> this URL
        from console.recording.foxglove_bridge import FoxgloveBridge
        try:
            bridge = FoxgloveBridge(app.recorder, robot, args.host, args.foxglove_port)
        except OSError as exc:  # taken between the check and the bind
            print(f"serve.py: --foxglove-port {args.foxglove_port}: {exc}", file=sys.stderr)
            life.shutdown(_shutdown_steps(app, server))
            return 2
    print(f"serve.py: {pin_console(app.services)}", file=sys.stderr)
    app.start()
    life.serving()  # from now on SIGTERM / Ctrl-C shut down in order (STOP and hardware ≤ 10 s, the rest ≤ 2 s)
    port = server.get_port()  # viser moves to the next free port if --port is taken
    if port != args.port:
        print(f"serve.py: PORT {args.port} IS BUSY: serving on {port} instead", file=sys.stderr,
              flush=True)
        if not args.next_free_port:  # taken between the check and the bind
            steps = _shutdown_steps(app, server)
            if bridge is not None:
                steps.append(("foxglove bridge", bridge.stop))
            life.shutdown(steps)
            return 2
    found = urls(args.host, port)
    print(f"Console for '{robot.name}' at {found[0]}  (Ctrl-C to stop)", flush=True)
    for url in found[1:]:
        print(f"  on the lab network: {url}", flush=True)
    if token is not None:
        print(f"Operator token: {token}   (Session panel -> Operator token -> Take control)",
              flush=True)
    else:
        print("No operator token (--no-token): any browser can take control.", flush=True)
    if app.access.first_client_takes_control:
        print("Desk mode: the first browser to connect gets control (--lab to disable).",
              flush=True)
    print(f"Data folder: {app.data.root}", flush=True)
    if bridge is not None:
        ws_url = urls(args.host, bridge.port)[0].replace("http://", "ws://").rstrip("/")
        print(f"Foxglove live data (read-only): {ws_url}", flush=True)
    try:
        life.wait()
    finally:
        steps = _shutdown_steps(app, server)
        if bridge is not None:
            steps.append(("foxglove bridge", bridge.stop))
        life.shutdown(steps)
    return 0


def _shutdown_steps(app: Any, server: Any) -> list[tuple[str, Any]]:
    """What shutting down does, in order (:meth:`Lifecycle.shutdown` bounds it)."""
    return [("STOP", lambda: app.core.stop_motion("console shutting down")),
            ("hardware", app.services.close),
            ("console threads", app.stop),
            ("web server", server.stop)]


if __name__ == "__main__":
    sys.exit(main())
