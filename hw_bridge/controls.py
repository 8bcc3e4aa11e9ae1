"""Operator commands for the bridge, queued by the UI and executed by the control thread.

GUI callbacks call :class:`QueuedBridgeControls` methods, which only enqueue; the control thread
(the only writer to hardware) calls :meth:`QueuedBridgeControls.apply_pending` once per cycle
and publishes :meth:`publish` a fresh :class:`~hw_bridge.interface.LinkHealth` for the UI.
"""

from __future__ import annotations

import dataclasses
import queue
from typing import Callable, Literal, Protocol

from hw_bridge.interface import HardwareInterface, LifecycleState, LinkHealth, ReturnType

Action = Literal["connect", "disconnect", "arm", "disarm"]


@dataclasses.dataclass(frozen=True)
class BridgeCommand:
    """One operator request."""

    action: Action
    port: str = ""
    baud: int = 0


class BridgeControls(Protocol):
    """What the Hardware panel needs; every method returns immediately."""

    def connect(self, port: str, baud: int) -> None: ...

    def disconnect(self) -> None: ...

    def arm(self) -> None: ...

    def disarm(self) -> None: ...

    def health(self) -> LinkHealth | None: ...


class QueuedBridgeControls:
    """BridgeControls backed by a queue drained by the control thread."""

    def __init__(self) -> None:
        self.commands: queue.SimpleQueue[BridgeCommand] = queue.SimpleQueue()
        self._health: LinkHealth | None = None

    def connect(self, port: str, baud: int) -> None:
        self.commands.put(BridgeCommand("connect", port.strip(), int(baud)))

    def disconnect(self) -> None:
        self.commands.put(BridgeCommand("disconnect"))

    def arm(self) -> None:
        self.commands.put(BridgeCommand("arm"))

    def disarm(self) -> None:
        self.commands.put(BridgeCommand("disarm"))

    def health(self) -> LinkHealth | None:
        return self._health

    def publish(self, health: LinkHealth) -> None:
        """Control thread: make a new snapshot visible to the UI (one reference swap)."""
        self._health = health

    def apply_pending(self, hw: HardwareInterface | None,
                      open_hw: Callable[[str, int], HardwareInterface]) -> HardwareInterface | None:
        """Control thread: run queued commands in order; returns the (possibly new) interface.

        ``connect`` builds a fresh interface with ``open_hw(port, baud)`` (after cleaning up the
        old one) and configures it; ``arm`` activates; faults land in ``hw.fault``.
        """
        while True:
            try:
                cmd = self.commands.get_nowait()
            except queue.Empty:
                return hw
            if cmd.action == "connect":
                if hw is not None:
                    hw.cleanup()
                if not cmd.port:
                    continue
                hw = open_hw(cmd.port, cmd.baud)
                hw.configure()
            elif hw is None:
                continue
            elif cmd.action == "disconnect":
                hw.cleanup()
            elif cmd.action == "arm" and hw.state is LifecycleState.INACTIVE:
                hw.activate()
            elif cmd.action == "disarm" and hw.state is LifecycleState.ACTIVE:
                if hw.deactivate() is ReturnType.ERROR:
                    hw.cleanup()
