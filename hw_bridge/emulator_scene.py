"""The soft-arm emulator's scene channel, so a test or the console can place the object the plant grasps.

:class:`SceneChannel` answers JSON datagrams on the emulator's UDP control socket
(``python -m hw_bridge.emulator --control-port P``, :mod:`hw_bridge.emulator`): place or
remove the object in the seeded plant's simulation, or read the scene (object, captured, the
finger's polyline). The emulator's loop calls :meth:`SceneChannel.serve` each pass; it never
blocks, and bad input gets an answer and changes nothing.
"""

from __future__ import annotations

import json
import math
import socket
from typing import Any, Callable


class SceneChannel:
    """The scene commands of one emulator: ``sock`` (bound, non-blocking), the plant's ``sim``
    (:class:`core.control.sim` simulation) and the emulator's event sink ``emit``."""

    def __init__(self, sock: socket.socket, sim: Any, emit: Callable[..., None]) -> None:
        self.sock, self.sim, self.emit = sock, sim, emit

    def serve(self) -> None:
        """Answer waiting scene datagrams (non-blocking; see the module docstring)."""
        while True:
            try:
                data, addr = self.sock.recvfrom(4096)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                return
            try:
                reply = self.command(json.loads(data))
            except Exception as exc:  # noqa: BLE001 - bad input: answer, change nothing
                reply = {"ok": False, "error": str(exc)}
            try:
                self.sock.sendto(json.dumps(reply).encode(), addr)
            except OSError:
                pass

    def command(self, msg: dict[str, Any]) -> dict[str, Any]:
        """The answer to one scene command (raises on bad input, before changing anything)."""
        sim = self.sim
        cmd = msg.get("cmd") if isinstance(msg, dict) else None
        if cmd == "place_object":
            x, y, r = (float(msg[k]) for k in ("x", "y", "r"))
            if not all(map(math.isfinite, (x, y, r))):
                raise ValueError("object x, y, r must be finite")
            sim.place_object(x, y, r)
            self.emit("object_placed", xy=[x, y], r=r)
            return {"ok": True}
        if cmd == "remove_object":
            sim.remove_object()
            return {"ok": True}
        if cmd == "scene":
            obj = sim.obj
            finger = sim.gripper_polyline().tolist() if sim.turn > 1e-3 else None
            return {"ok": True, "captured": sim.captured, "finger": finger,
                    "object": None if obj is None else [*map(float, obj.xy), obj.radius]}
        raise ValueError(f"unknown scene command {cmd!r}")
