"""Device emulator on a pseudo-terminal, so the whole serial stack runs without hardware.

``python -m hw_bridge.emulator --robot extensible|soft-arm [--baud B] [--drop P] [--corrupt P]
[--stall-after S] [--disconnect-after S [--disconnect-for D]] [--motors N] [--mocap-port P]
[--seed S] [--object X Y R] [--control-port P] [--slip F [--slip-jitter J]] [--tip-port P
[--tip-noise M]] [--mid-range]``

* stdout line 1: the pty slave path (open it with pyserial); later lines: JSON events
  (``{"event": "watchdog_tripped", "t": ..., "positions": [...]}``, armed, disarmed,
  link_cut, link_restored, stalled, status on SIGUSR1, exit).
* Wire time at ``--baud``: each direction is a serial line delivering ``10/baud`` s per byte
  (``--baud 0``: no wire model, like the Due's native USB port).
* Faults: ``--drop P`` / ``--corrupt P`` drop or bit-flip each outgoing frame and each incoming
  chunk with probability P; ``--stall-after S`` freezes the device (no processing, no output,
  like a hung MCU); ``--disconnect-after S`` cuts the wire (bytes lost both ways, the device
  keeps running so its watchdog acts) for ``--disconnect-for D`` s (default: for good).
* SIGUSR2 toggles the hardware e-stop input. SIGTERM/SIGINT exit cleanly.

Soft arm: the plant is :class:`core.control.sim.EmulatorPlant` (the console's seeded soft-arm
sim: stick-slip, pre-pressure stiffening, object and gripper, marker noise and occlusions)
driven by the encoder positions; every tick one UDP motion-capture frame goes to
``127.0.0.1:--mocap-port``: base, segment ends (NaN while occluded, ``valid`` false), then the
object centre while an object is present. ``--object X Y R`` places a disc at start.
``--control-port P`` (0: any free port) opens a scene channel on ``127.0.0.1:P`` (stdout event
``{"event": "control", "port": N}``); datagrams are JSON, each answered to the sender with
``{"ok": true, ...}`` or ``{"ok": false, "error": ...}``:
``{"cmd": "place_object", "x": X, "y": Y, "r": R}``, ``{"cmd": "remove_object"}``,
``{"cmd": "scene"}`` (answer: ``object`` [x, y, r] or null, ``captured``, ``finger`` polyline
or null). It stands in for moving the real object by hand.

Extensible arm: ``--slip F`` makes the racks slip on their pinions
(:mod:`core.control.rack_slip`: each move loses F of its travel on the proximal platform, less
on distal ones, plus a per-move random part of standard deviation ``--slip-jitter``; the
encoders do not see it). ``--tip-port P`` sends the tip, as a mocap-like measurement with
Gaussian noise ``--tip-noise`` (m per axis), every tick to ``127.0.0.1:P`` in the motion-capture
packet (one point: x, y, z in m). Without these flags the racks follow the encoders exactly.
The racks power up retracted (every one at rack_min); ``--mid-range`` starts them at the
console's start pose (straight, mid-range: :func:`core.kinematics.delta.mid_range_delta`), so
connecting and arming the console moves nothing.

This module is the command line (argument checks, JSON event lines on stdout, signals); the
emulator itself is :class:`hw_bridge.pty_emulator.Emulator`.
"""

from __future__ import annotations

import argparse
import os
import dataclasses
import json
import math
import signal
import sys
import time
from typing import Any

from core.robots import load
from hw_bridge.device_events import EVENT_LOG_ENV, LOUD_EVENTS, HostWatch, describe_event
from hw_bridge.parent_watch import parent_pid_from_env
from hw_bridge.pty_emulator import Emulator, EmulatorOptions


class EventSink:
    """stdout (the host's pipe) + the log file + stderr for :data:`LOUD_EVENTS`."""

    def __init__(self, log_path: str | None, loud: bool):
        self.log_path = log_path or None
        self.loud = loud
        self.stdout_open = True

    @classmethod
    def from_env(cls) -> "EventSink":
        """Configured by the starting console (log path; loud when a console started us)."""
        return cls(os.environ.get(EVENT_LOG_ENV), parent_pid_from_env() is not None)

    def emit(self, event: str, **fields: Any) -> None:
        record = {"event": event, "t": round(time.monotonic(), 4), **fields}
        line = json.dumps(record)
        if self.stdout_open:
            try:
                print(line, flush=True)
            except (BrokenPipeError, OSError, ValueError):
                self.stdout_open = False  # the host is gone: the file and stderr remain
        if self.log_path:
            stamped = {"wall": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "pid": os.getpid(), **record}
            try:
                with open(self.log_path, "a", encoding="utf-8") as f:
                    f.write(json.dumps(stamped) + "\n")
            except OSError:
                pass
        if self.loud and event in LOUD_EVENTS:
            try:
                print(f"device emulator (pid {os.getpid()}): {describe_event(record)}", file=sys.stderr,
                      flush=True)
            except (OSError, ValueError):
                pass



def options_from_args(args: argparse.Namespace) -> EmulatorOptions:
    """The parsed command line as :class:`EmulatorOptions`."""
    values = {f.name: getattr(args, f.name) for f in dataclasses.fields(EmulatorOptions)}
    if values["object"] is not None:
        values["object"] = tuple(values["object"])
    return EmulatorOptions(**values)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="python -m hw_bridge.emulator", description=__doc__.split("\n")[0])
    ap.add_argument("--robot", required=True, help="robot name (extensible, soft-arm) or TOML path")
    ap.add_argument("--baud", type=int, default=None, help="wire model baud rate (0: none); "
                    "default [bridge].baud")
    ap.add_argument("--drop", type=float, default=0.0, help="probability of dropping a frame")
    ap.add_argument("--corrupt", type=float, default=0.0, help="probability of flipping a bit")
    ap.add_argument("--stall-after", type=float, default=None, metavar="S")
    ap.add_argument("--disconnect-after", type=float, default=None, metavar="S")
    ap.add_argument("--disconnect-for", type=float, default=None, metavar="D")
    ap.add_argument("--motors", type=int, default=None, help="override the channel count")
    ap.add_argument("--mocap-port", type=int, default=None, help="UDP port (soft arm)")
    ap.add_argument("--seed", type=int, default=None,
                    help="random seed of fault injection and of the soft-arm sim (default 0)")
    ap.add_argument("--object", type=float, nargs=3, default=None, metavar=("X", "Y", "R"),
                    help="soft arm: place a disc of radius R (m) at (X, Y) on the table")
    ap.add_argument("--control-port", type=int, default=None, metavar="P",
                    help="soft arm: UDP scene channel on 127.0.0.1:P (0: any free port)")
    ap.add_argument("--sched-priority", type=int, default=0, metavar="P",
                    help="run the device under SCHED_FIFO at priority P (1-99; 0: normal), like "
                         "a dedicated microcontroller that nothing else on the machine delays")
    ap.add_argument("--cpus", default=None, metavar="LIST",
                    help="run on these CPUs (comma-separated), moved there once started up, "
                         "e.g. the real-time CPU of hw_bridge.cpu_partition")
    ap.add_argument("--slip", type=float, default=None, metavar="F",
                    help="extensible arm: racks slip on their pinions, losing F (0..0.5) of each "
                         "move's travel on the proximal platform (default: no slip)")
    ap.add_argument("--slip-jitter", type=float, default=0.015, metavar="J",
                    help="standard deviation of the per-move random part of the slip fraction")
    ap.add_argument("--tip-port", type=int, default=None, metavar="P",
                    help="extensible arm: send the measured tip to UDP 127.0.0.1:P every tick")
    ap.add_argument("--tip-noise", type=float, default=0.002, metavar="M",
                    help="tip measurement noise, m per axis (default 0.002)")
    ap.add_argument("--mid-range", action="store_true",
                    help="extensible arm: the racks start at mid-range (the console's start "
                         "pose), not retracted")
    args = ap.parse_args(argv)
    if args.slip is not None and not 0.0 <= args.slip <= 0.5:
        ap.error("--slip must be in [0, 0.5]")
    if not (math.isfinite(args.slip_jitter) and args.slip_jitter >= 0
            and math.isfinite(args.tip_noise) and args.tip_noise >= 0):
        ap.error("--slip-jitter and --tip-noise must be finite and >= 0")
    if args.tip_port is not None and not 1 <= args.tip_port <= 65535:
        ap.error("--tip-port must be in 1..65535")
    if args.cpus is not None:
        from hw_bridge.cpu_partition import parse_cpus
        try:
            args.cpus = parse_cpus(args.cpus)
        except ValueError as exc:
            ap.error(f"--cpus: {exc}")
    if not 0 <= args.sched_priority <= 99:
        ap.error("--sched-priority must be in 0..99")
    if args.object is not None and (not all(map(math.isfinite, args.object))
                                    or not args.object[2] > 0):
        ap.error("--object needs finite X Y and a radius R > 0")
    if args.control_port is not None and not 0 <= args.control_port <= 65535:
        ap.error("--control-port must be in 0..65535")
    for name in ("drop", "corrupt"):
        if not 0.0 <= getattr(args, name) <= 1.0:
            ap.error(f"--{name} must be a probability in [0, 1]")
    if args.motors is not None and not 1 <= args.motors <= 32:
        ap.error("--motors must be in 1..32")
    if args.baud is not None and args.baud < 0:
        ap.error("--baud must be >= 0")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        robot = load(args.robot)
        sink = EventSink.from_env()  # stdout, + log file and stderr when a console started us
        emu = Emulator(robot, options_from_args(args), sink.emit)
        emu.host_watch = HostWatch(sink)  # host died: log the watchdog's trip, then exit
    except Exception as exc:  # noqa: BLE001 - report any setup failure plainly
        print(f"emulator: {exc}", file=sys.stderr)
        return 2
    print(emu.path, flush=True)
    if emu.control is not None:
        sink.emit("control", port=emu.control.getsockname()[1])

    def _stop(signum: int, frame: object) -> None:
        emu.stop = True

    def _flag(name: str) -> Any:
        return lambda signum, frame: emu.requests.add(name)

    signal.signal(signal.SIGTERM, _stop)
    signal.signal(signal.SIGINT, _stop)
    signal.signal(signal.SIGUSR1, _flag("status"))
    signal.signal(signal.SIGUSR2, _flag("estop"))
    emu.run()
    return 0


if __name__ == "__main__":
    sys.exit(main())
