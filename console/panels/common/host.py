"""What a panel may use of the console, as a Protocol, so no panel imports the app itself.

:class:`PanelHost` lists the console's members panels read (the app satisfies it structurally:
``console.app.ConsoleApp``). Panels reach motion and safety only through ``core`` (the one STOP
and the motion routes, :class:`console.core.console_core.ConsoleCore`); they render state and
send commands, and keep no state but their handles.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    import viser

    from console.client_guard import ClientGuard
    from console.core.access import AccessControl, NotOperator
    from console.core.console_core import ConsoleCore
    from console.core.datadir import DataDir
    from console.core.design_study import DesignStudies
    from console.core.grasp_session import GraspSession
    from console.core.model import ArmModel
    from console.core.services import ConsoleServices
    from console.core.state import StateStore
    from console.panels.common.header import ConsoleHeader
    from console.recording.recorder import Recorder
    from console.scene.arm_view import ArmView
    from console.panels.common.tabs import ConsoleTabs
    from core.robots import Robot


class PanelHost(Protocol):
    """The console as its panels see it (``Panel.app``)."""

    robot: Robot
    model: ArmModel
    store: StateStore
    services: ConsoleServices
    core: ConsoleCore
    access: AccessControl
    recorder: Recorder
    server: viser.ViserServer
    header: ConsoleHeader
    tabs: ConsoleTabs
    view: ArmView
    guard: ClientGuard
    grasp_session: GraspSession | None
    design_study: DesignStudies
    camera_presets: Any
    data_root: Path

    @property
    def data(self) -> DataDir:
        """The console's data folder."""
        ...

    @property
    def stopped(self) -> bool:
        """Whether the console is shutting down."""
        ...

    @property
    def panels(self) -> tuple[Any, ...]:
        """The composed panels."""
        ...

    def refuse(self, client: Any, exc: NotOperator | str, action: str = "") -> None:
        """Tell ``client`` why it may not act."""
        ...

    def show_refusal(self, client: Any, title: str, message: str) -> None:
        """Tell ``client`` why something was refused, shown until its next action."""
        ...

    def clear_refusal(self, client: Any) -> None:
        """Remove ``client``'s standing refusal (its next action is under way)."""
        ...

    def notify_all(self, title: str, body: str, color: str = "blue",
                   coalesce_s: float = 0.0) -> None:
        """A notification on every connected browser."""
        ...

    def arm_reach(self) -> float: ...

    def keep_in_view(self, point: Any) -> list[int]:
        """Keep a world point (m; None: none) in every browser's view (re-framing if needed)."""
        ...

    def table_rectangle(self) -> tuple[float, float, float, float]: ...
