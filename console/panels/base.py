"""The panel contract: one class per GUI panel, owning its handles, composed by ConsoleApp.

A panel subclasses :class:`Panel`, sets ``title`` / ``order`` (smaller is higher in the control
panel) and, if it only makes sense for one robot, ``kinds``; builds its widgets in
:meth:`Panel.build` (called inside the panel's own folder, so ``self.gui.add_*`` lands there) and
keeps the handles as attributes. Rules:

* Callbacks stay thin: read the widget, then ``self.app.store.request(q, source)`` or
  ``self.app.store.edit(fn, source)`` (validated, clamped, thread-safe), or hand work to your own
  worker. Never draw the arm or block in a callback.
* Display updates happen in :meth:`Panel.on_state`, called by the app's single render thread,
  rate-limited, with only the newest :class:`~console.state.ArmState`.
* Server-side assignments to a widget's ``value`` re-run its ``on_update`` callbacks with
  ``event.client is None``; callbacks that mirror state into widgets should ignore those.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

from console.state import ArmState

if TYPE_CHECKING:
    from console.app import ConsoleApp
    from core.robots import Robot


class Panel:
    """Base class of console panels (see the module docstring for the contract)."""

    title: ClassVar[str] = "Panel"
    order: ClassVar[float] = 100.0
    kinds: ClassVar[tuple[str, ...]] = ("planar", "delta")
    expand_by_default: ClassVar[bool] = True

    def __init__(self, app: ConsoleApp) -> None:
        self.app = app
        self.gui = app.server.gui
        self.folder = self.gui.add_folder(self.title, order=self.order,
                                          expand_by_default=self.expand_by_default)
        with self.folder:
            self.build()

    @classmethod
    def supports(cls, robot: Robot) -> bool:
        """Whether this panel applies to ``robot`` (by its kinematic kind)."""
        return robot.kind in cls.kinds

    def build(self) -> None:
        """Create the widgets (inside this panel's folder) and attach thin callbacks."""
        raise NotImplementedError

    def on_state(self, state: ArmState) -> None:
        """Show the newest displayed state; runs on the render thread, keep it cheap."""

    def close(self) -> None:
        """Remove the panel's widgets."""
        self.folder.remove()
