"""The Hardware panel's view of an arm's link: enqueue-only verbs and the newest health.

GUI callbacks call :class:`BridgeControls` methods, which only enqueue a bridge command
(:mod:`hw_bridge.commands`); the arm's loop thread (the only writer to hardware) runs it through
its :class:`hw_bridge.link_supervisor.LinkSupervisor` and publishes a fresh
:class:`~hw_bridge.interface.LinkHealth` for the UI. :class:`QueuedBridgeControls` is the
in-process queue (the extensible runner's); the soft arm's control process offers the same
verbs over its pipe (:class:`hw_bridge.loop_process.ProcessBridgeControls`).
"""

from __future__ import annotations

import queue
from typing import Protocol

from hw_bridge.commands import Arm, BridgeCommand, Connect, Disarm, Disconnect
from hw_bridge.interface import LinkHealth


class BridgeControls(Protocol):
    """What the Hardware panel needs; every method returns immediately."""

    def connect(self, port: str, baud: int) -> None: ...

    def disconnect(self) -> None: ...

    def arm(self) -> None: ...

    def disarm(self) -> None: ...

    def health(self) -> LinkHealth | None: ...


class QueuedBridgeControls:
    """BridgeControls backed by a queue the loop thread drains (see :meth:`LinkSupervisor.apply`)."""

    def __init__(self) -> None:
        self.commands: queue.SimpleQueue[BridgeCommand] = queue.SimpleQueue()
        self._health: LinkHealth | None = None

    def connect(self, port: str, baud: int) -> None:
        self.commands.put(Connect(port.strip(), int(baud)))

    def disconnect(self) -> None:
        self.commands.put(Disconnect())

    def arm(self) -> None:
        self.commands.put(Arm())

    def disarm(self) -> None:
        self.commands.put(Disarm())

    def health(self) -> LinkHealth | None:
        return self._health

    def publish(self, health: LinkHealth) -> None:
        """Control thread: make a new snapshot visible to the UI (one reference swap)."""
        self._health = health
