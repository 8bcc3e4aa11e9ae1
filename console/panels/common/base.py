"""The panel contract: one class per GUI panel, owning its handles, composed by ConsoleApp.

A panel subclasses :class:`Panel`, sets ``title``, ``tab`` (its task's tab: ``Operate``,
``Hardware``, ``Experiments`` or ``Session``, see ``console.panels.common.tabs``), ``order`` (smaller is higher
in its tab) and, if it only makes sense for one robot, ``kinds``; builds its widgets in
:meth:`Panel.build` (called inside the panel's own folder, so ``self.gui.add_*`` lands there) and
keeps the handles as attributes. Rules:

* Callbacks stay thin: read the widget, then ``self.app.store.request(q, source)`` or
  ``self.app.store.edit(fn, source)`` (validated, clamped, thread-safe), or hand work to your own
  worker. Never draw the arm or block in a callback.
* Display updates happen in :meth:`Panel.on_state`, called by the app's single render thread,
  rate-limited, with only the newest :class:`~console.core.state.ArmState`.
* Server-side assignments to a widget's ``value`` re-run its ``on_update`` callbacks with
  ``event.client is None``; callbacks that mirror state into widgets should ignore those.

Who may act (shared console, one operator): every callback that moves the arm, plans-and-
executes, arms/disarms or changes the hardware MUST be wrapped with :func:`operator_only`, so
the check cannot be forgotten and is the same everywhere::

    class MyPanel(Panel):
        def build(self) -> None:
            self.go = self.gui.add_button("Execute")
            self.go.on_click(self._on_execute)
            self.arm_btn.on_click(operator_only(lambda _: self._arm(), panel=self, action="arm"))

        @operator_only(action="execute a plan")
        def _on_execute(self, event: viser.GuiEvent) -> None:
            ...  # runs only for the operator's clicks

Below the callbacks, ``console.web.client_guard`` refuses a viewer's edit of any shared input
before viser stores or broadcasts it, unless the panel marked the widget with
:meth:`Panel.allow_viewers` (STOP, Save scene, exports); a browser's own ``client.gui`` widgets
are its own. ``operator_only`` stays as the second line (and names the action in the refusal).
A viewer's event never reaches the callback: the viewer gets a notification ("Only the operator
can execute a plan -- Alice holds control; ask them or take control with the token"), the
refusal is recorded, and :meth:`Panel.on_refused` runs so input widgets can snap back (viser
has already shown the viewer's new slider value to everyone). Events with ``event.client is
None`` (server-side value mirrors) pass through. Code that is not a GUI callback can call
``self.app.access.check(client, "jog")``, which raises ``console.core.access.NotOperator(reason)``.
Panels never wire safety: STOP (any client), a lost lease, Release, hold-to-run expiry, link
loss and a dead loop all end motion in ``self.app.core.stop_motion`` whatever panels exist. A
panel that starts a motion later (after a plan, on a worker) starts it through
``self.app.core.start_motion`` / ``run_if_current`` / ``run_expected``, so none is queued behind
a STOP; it reads ``core.stop_generation`` / ``core.last_stop`` to show what stopped.
Actions worth keeping go to ``self.app.recorder.log(kind, payload, event.client)``.
"""

from __future__ import annotations

import functools
import inspect
from typing import TYPE_CHECKING, Any, Callable, ClassVar, TypeVar, cast, overload

from console.panels.common.events import client_of
from console.core.access import NotOperator
from console.core.state import ArmState

if TYPE_CHECKING:
    from console.panels.common.host import PanelHost
    from core.robots import Robot


class Panel:
    """Base class of console panels (see the module docstring for the contract)."""

    title: ClassVar[str] = "Panel"
    tab: ClassVar[str] = "Operate"  # one of console.panels.common.tabs.TAB_ORDER
    order: ClassVar[float] = 100.0
    kinds: ClassVar[tuple[str, ...]] = ("planar", "delta")
    expand_by_default: ClassVar[bool] = True

    def __init__(self, app: PanelHost) -> None:
        self.app = app
        self.gui = app.server.gui
        self._on_close: list[Callable[[], None]] = []  # e.g. removers of session listeners
        with app.tabs.tab(self.tab):
            self.folder = self.gui.add_folder(self.title, order=self.order,
                                              expand_by_default=self.expand_by_default)
        with self.folder:
            self.build()
        self.after_build()

    @classmethod
    def supports(cls, robot: Robot) -> bool:
        """Whether this panel applies to ``robot`` (by its kinematic kind)."""
        return robot.kind in cls.kinds

    def build(self) -> None:
        """Create the widgets (inside this panel's folder) and attach thin callbacks."""
        raise NotImplementedError

    def after_build(self) -> None:
        """Work that must run outside the folder's ``with`` block (a folder handle may be
        entered only once at a time), e.g. per-browser widgets for browsers already connected."""

    def on_state(self, state: ArmState) -> None:
        """Show the newest displayed state; runs on the render thread, keep it cheap."""

    def on_idle(self) -> None:
        """No new displayed state for a while (render thread): show anything held back."""

    def close(self) -> None:
        """Stop listening (:meth:`when_closed`) and remove the panel's widgets."""
        for undo in reversed(self._on_close):
            undo()
        self._on_close.clear()
        self.folder.remove()

    def when_closed(self, undo: Callable[[], None]) -> None:
        """Run ``undo`` when the panel closes: a listener's remover (a session that outlives the
        panel must not call into its removed widgets)."""
        self._on_close.append(undo)

    def on_refused(self, event: Any) -> None:
        """A viewer's event was refused by :func:`operator_only`; undo what it showed (optional)."""

    def allow_viewers(self, *handles: Any) -> None:
        """Let viewers use these shared widgets (STOP, downloads); every other shared input is
        the operator's, refused by ``console.web.client_guard`` before viser stores it."""
        self.app.guard.allow_viewers(*handles)

    def operator_only(self, callback: F, action: str | None = None) -> F:
        """``callback`` wrapped by :func:`operator_only` for this panel (for lambdas)."""
        return operator_only(callback, panel=self, action=action)


F = TypeVar("F", bound=Callable[..., Any])


def _find_event(args: tuple[Any, ...], kwargs: dict[str, Any]) -> Any:
    for value in (*reversed(args), *kwargs.values()):
        if hasattr(value, "client") and hasattr(value, "client_id"):
            return value
    return None


def _action_of(fn: Callable[..., Any]) -> str:
    name = getattr(fn, "__name__", "") or ""
    name = name.removeprefix("_").removeprefix("on_").replace("_", " ").strip()
    return name if name and name != "<lambda>" else "do that"


@overload
def operator_only(callback: F, *, panel: Panel | None = None, action: str | None = None) -> F: ...


@overload
def operator_only(callback: None = None, *, panel: Panel | None = None,
                  action: str | None = None) -> Callable[[F], F]: ...


def operator_only(callback: Any = None, *, panel: Panel | None = None,
                  action: str | None = None) -> Any:
    """Run a GUI callback only for the operator's events (see the module docstring).

    Use as ``@operator_only`` / ``@operator_only(action="jog")`` on a Panel method, or wrap a
    callback at registration: ``operator_only(fn, panel=self, action="arm")``. ``action`` is the
    verb phrase shown to refused viewers ("Only the operator can <action> ...").
    """

    def decorate(fn: F) -> F:
        what = action or _action_of(fn)

        def gate(args: tuple[Any, ...], kwargs: dict[str, Any]) -> bool:
            event = _find_event(args, kwargs)
            client = client_of(event)
            if client is None:  # a server-side mirror or a programmatic call: no browser
                return True
            owner = panel
            if owner is None and args and isinstance(args[0], Panel):
                owner = args[0]
            if owner is None:
                owner = getattr(fn, "__self__", None)
            if not isinstance(owner, Panel):
                raise TypeError(f"operator_only({fn!r}) needs panel= (not a Panel method)")
            try:
                owner.app.access.check(client, what)
            except NotOperator as exc:
                owner.app.refuse(client, exc, what)
                owner.on_refused(event)
                return False
            owner.app.clear_refusal(client)  # the operator's next action: the last refusal goes
            return True

        if inspect.iscoroutinefunction(fn):
            @functools.wraps(fn)
            async def async_wrapper(*args: Any, **kwargs: Any) -> Any:
                if gate(args, kwargs):
                    return await fn(*args, **kwargs)
                return None

            setattr(async_wrapper, "operator_only", what)  # what the gate names (tests read it)
            return cast(F, async_wrapper)

        @functools.wraps(fn)
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            if gate(args, kwargs):
                return fn(*args, **kwargs)
            return None

        setattr(wrapper, "operator_only", what)
        return cast(F, wrapper)

    if callback is not None:
        return decorate(callback)
    return decorate
