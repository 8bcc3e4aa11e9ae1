"""What attaching the console to hardware started, apart from starting it: so it can be stopped.

:func:`console.core.hardware_setup.attach` fills a :class:`HardwareAttachment`;
:class:`console.core.services.ConsoleServices` carries it (``services.hardware``) and closes it.
It lives below both, so the services need not import the module that builds them.
"""

from __future__ import annotations

import dataclasses
from typing import Callable, Literal

LinkKind = Literal["emulator", "mock", "port"]


@dataclasses.dataclass
class HardwareAttachment:
    """What :func:`console.core.hardware_setup.attach` started, so :meth:`close` stops it in order.

    Attributes:
        description: One line for the status bar and the terminal.
        kind: ``"emulator"`` (device emulator on a pty), ``"mock"`` (in-process device, no
            serial) or ``"port"`` (a real controller).
        port_path: The serial device the console uses, when known here: ``--port-path``, or the
            extensible arm's emulator pty. None for the soft arm's emulator (its control process
            starts it; the Hardware panel takes the path from the link health) and for the mock.
        baud: The link's baud rate (``[bridge] baud`` of the robot file).
        closers: What :meth:`close` calls, in order (loops first).
    """

    description: str
    kind: LinkKind = "mock"
    port_path: str | None = None
    baud: int = 1_000_000
    closers: list[Callable[[], object]] = dataclasses.field(default_factory=list)

    def close(self) -> None:
        """Stop loops first, then links and the emulator process."""
        for close in self.closers:
            try:
                close()
            except Exception:  # noqa: BLE001 - shutting down: keep closing the rest
                pass
        self.closers.clear()
