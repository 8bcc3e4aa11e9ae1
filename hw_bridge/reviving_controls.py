"""A reconnect brings a dead device emulator back: the extensible arm's Hardware panel verbs.

The soft arm's control process starts its emulator itself and replaces a dead one on Connect
(:meth:`hw_bridge.soft_arm_worlds.HardwareWorld.revive_emulator`). The extensible arm's
emulator is started by the console (``console.core.hardware_setup``), so its
:class:`~hw_bridge.controls.BridgeControls` are wrapped in :class:`RevivingControls`: a Connect
while the emulator is dead (killed, crashed) starts a new one, in a thread (the verbs return at
once), and connects to its pty instead of the dead one's. Every other verb passes through.
"""

from __future__ import annotations

import logging
import threading
from typing import Any, Callable

from hw_bridge.controls import BridgeControls
from hw_bridge.interface import LinkHealth

log = logging.getLogger(__name__)


class RevivingControls:
    """:class:`~hw_bridge.controls.BridgeControls` that restart a dead emulator on Connect.

    Args:
        controls: The loop's own controls.
        emulator: The running emulator (an ``EmulatorProcess``: ``proc``, ``path``, ``stop``).
        start: Starts a new emulator like the first one.
        on_new_path: Told each new emulator's pty path (the attachment's port, the loop's
            port for a restart of its process).
    """

    def __init__(self, controls: BridgeControls, emulator: Any, start: Callable[[], Any],
                 on_new_path: Callable[[str], None] = lambda path: None) -> None:
        self.controls = controls
        self.emulator = emulator
        self.start = start
        self.on_new_path = on_new_path
        self.revive_fault: str | None = None  # why the last revival failed (None: it did not)
        self._lock = threading.Lock()

    @property
    def emulator_alive(self) -> bool:
        return self.emulator.proc.poll() is None

    def connect(self, port: str, baud: int) -> None:
        if self.emulator_alive:
            self.controls.connect(port, baud)
            return
        threading.Thread(target=self._revive, args=(port, baud), name="emulator-revive",
                         daemon=True).start()

    def _revive(self, port: str, baud: int) -> None:
        with self._lock:
            old = self.emulator
            if old.proc.poll() is not None:  # (not revived by a Connect just before)
                try:
                    old.stop()  # reaped
                    self.emulator = self.start()
                except Exception as exc:  # noqa: BLE001 - shown in health() until it works
                    log.exception("restarting the device emulator failed")
                    self.revive_fault = f"the device emulator did not start: {exc}"
                    return
                self.revive_fault = None
                self.on_new_path(self.emulator.path)
            if port.strip() in ("", old.path):
                port = self.emulator.path
        self.controls.connect(port, baud)

    def disconnect(self) -> None:
        self.controls.disconnect()

    def arm(self) -> None:
        self.controls.arm()

    def disarm(self) -> None:
        self.controls.disarm()

    def health(self) -> LinkHealth | None:
        return self.controls.health()

    def stop(self) -> None:
        """Stop the current emulator (the console is closing)."""
        self.emulator.stop()
