"""The extensible arm's console panels, in one list for ``ConsoleApp`` to compose.

``EXTENSIBLE_PANELS`` = tip target (gizmo / typed, IK), box obstacles (shelves, drawer walls the
IK and paths keep clear of), paths (preview, execute, stop, error plot) and repeatability
(Table I). Each has ``kinds = ("delta",)``, so composing them for the
soft arm adds nothing. Execution goes through ``app.services.extensible_runner``, the runner
``console.core.hardware_setup.attach`` built on the emulator, the board or an in-process MockHardware.
"""

from __future__ import annotations

from console.panels.common.base import Panel
from console.panels.extensible.obstacles_boxes import BoxObstaclesPanel
from console.panels.extensible.paths import PathsPanel
from console.panels.extensible.repeatability import RepeatabilityPanel
from console.panels.extensible.target import TargetPanel

EXTENSIBLE_PANELS: list[type[Panel]] = [TargetPanel, BoxObstaclesPanel, PathsPanel,
                                         RepeatabilityPanel]

__all__ = ["EXTENSIBLE_PANELS", "BoxObstaclesPanel", "PathsPanel", "RepeatabilityPanel",
           "TargetPanel"]
