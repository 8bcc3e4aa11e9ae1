"""The console's services, typed and built once: what the panels use beyond the app itself.

``serve.py`` builds one :class:`ConsoleServices` (through
:func:`console.core.hardware_setup.attach`) and passes it to ``ConsoleApp(..., services=...)``;
panels read ``app.services.soft_control``, ``app.services.bridge_controls``, ... Nothing is
looked up by name on the app and nothing is created behind the caller's back: a service a robot
or a test does not have is None, and a panel that needs it says so.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from console.core.demo_motion import DemoMotion
    from console.core.hardware_attachment import HardwareAttachment
    from hw_bridge.controls import BridgeControls
    from hw_bridge.cpu_partition import CpuPartition
    from hw_bridge.extensible_closed_loop import TipSensor
    from hw_bridge.extensible_process import ExtensibleProcess
    from hw_bridge.soft_arm_process import ControlProcess


@dataclasses.dataclass(frozen=True)
class ConsoleServices:
    """Everything the console runs besides its GUI, for one robot.

    Attributes:
        hardware: What :func:`console.core.hardware_setup.attach` started (link kind, port, baud;
            :meth:`close` stops it all). None: no hardware (kinematic simulation).
        soft_control: The soft arm's control process (its 100 Hz loop; Control panel).
        extensible_runner: The extensible arm's 100 Hz runner in its own process (Paths,
            Target, Repeatability).
        bridge_controls: The loop's connect / disconnect / arm / disarm / health for the
            Hardware panel (None: the loop offers none, e.g. the extensible arm's in-process mock).
        cpu_partition: Where the real-time loop runs and where everything else does (None: no
            pinning).
        demo: The "Run demo motion" button's motion (``serve.py --demo``; None: no button).
        tip_sensor: The extensible arm's tip measurement
            (:class:`hw_bridge.extensible_closed_loop.TipSensor`; ``serve.py --slip F`` on the
            emulator; None: none, the Repeatability panel measures with the encoders).
    """

    hardware: HardwareAttachment | None = None
    soft_control: ControlProcess | None = None
    extensible_runner: ExtensibleProcess | None = None
    bridge_controls: BridgeControls | None = None
    cpu_partition: CpuPartition | None = None
    demo: DemoMotion | None = None
    tip_sensor: TipSensor | None = None

    def close(self) -> None:
        """Stop what was started: the demo, then loops, links and the emulator."""
        if self.demo is not None:
            self.demo.stop()
        if self.hardware is not None:
            self.hardware.close()

    def replace(self, **changes: Any) -> ConsoleServices:
        """A copy with ``changes`` (the dataclass is frozen)."""
        return dataclasses.replace(self, **changes)
