"""The console's always-visible header: the one STOP, who holds control, the phase, the link.

It sits above the tabs (``console.panels.common.tabs``), so on a desktop, a tablet (820x1180) or a phone
(390x844) STOP and the arm's phase are on screen without scrolling, whichever tab is open.
STOP works for everyone (viewers too, also the ``Esc`` hotkey through viser's command palette).

Panels own what the fields say and push it here with :meth:`ConsoleHeader.show`::

    app.header.show("phase", "moving · waypoint 3/8", tone="busy")
    app.header.show("link", "emulator · active · ARMED")

Phase and Link describe the arm's loop process, so with one they go through
``app.loop_header`` (:class:`console.panels.common.loop_header.LoopHeader`), which shows a panel's wording
only while the loop's view is fresh and says otherwise that the loop died or went silent.

Fields are shown in :data:`FIELDS` order; an empty text hides a field. ``tone`` colours the
field's text (``ok``, ``busy``, ``warn``, ``fault`` or ``None`` for plain).
"""

from __future__ import annotations

import html
import threading
from typing import TYPE_CHECKING, Any, Callable

import viser

from console.panels.common.events import client_of, connected
from console.core.arm_status import Tone

if TYPE_CHECKING:
    from console.core.console_core import ConsoleCore

STOP_HOTKEY = "escape"
FIELDS: tuple[str, ...] = ("control", "phase", "link")
LABELS = {"control": "Control", "phase": "Phase", "link": "Link"}
TONE_COLORS: dict[str, str] = {"ok": "#2b8a3e", "busy": "#1c7ed6", "warn": "#e67700",
                               "fault": "#c92a2a"}


class ConsoleHeader:
    """STOP and the status fields above the tabs (see the module docstring).

    Args:
        gui: The server's GUI to draw into.
        core: The console core; STOP calls ``core.stop_motion`` (the one safety route).
        allow_viewers: Lets viewers use STOP (``ClientGuard.allow_viewers``).
        notify_all: Tells every browser who pressed STOP (``ConsoleApp.notify_all``).
        stopped: Whether the console is shutting down (no GUI updates then).
    """

    def __init__(self, gui: viser.GuiApi, core: ConsoleCore, *,
                 allow_viewers: Callable[..., None],
                 notify_all: Callable[..., None],
                 stopped: Callable[[], bool] = lambda: False) -> None:
        self.core = core
        self._notify_all = notify_all
        self._stopped = stopped
        self._lock = threading.Lock()
        self._fields: dict[str, tuple[str, str | None]] = {}
        self._shown = ""
        self.stop_btn = gui.add_button("STOP  (Esc)", color="red", icon=viser.Icon.HAND_STOP,
                                       hint="Stops the arm. Works for everyone (hotkey: Esc).",
                                       order=0.1)
        self.stop_btn.on_click(self._on_stop)
        self.stop_cmd = gui.add_command("STOP the arm", description="Stops all motion",
                                        hotkey=STOP_HOTKEY)
        self.stop_cmd.on_trigger(self._on_stop)
        self.status = gui.add_html(self._render(), order=0.2)
        allow_viewers(self.stop_btn, self.stop_cmd)

    def show(self, field: str, text: str, tone: Tone | None = None, *,
             escape: bool = True) -> None:
        """Set one field's text (empty hides it); sends only when the header changes."""
        if field not in FIELDS:
            raise ValueError(f"unknown header field {field!r}; fields: {', '.join(FIELDS)}")
        body = html.escape(text) if escape else text
        with self._lock:
            self._fields[field] = (body, tone)
            page = self._render()
            if page == self._shown or self._stopped():
                return
            self._shown = page
        self.status.content = page

    def text(self, field: str) -> str:
        """The field's current text as HTML (empty when unset)."""
        with self._lock:
            return self._fields.get(field, ("", None))[0]

    def _render(self) -> str:
        parts = []
        for field in FIELDS:
            body, tone = self._fields.get(field, ("", None))
            if not body:
                continue
            style = f' style="color:{TONE_COLORS[tone]}"' if tone in TONE_COLORS else ""
            parts.append(f'<span data-testid="header-{field}"><b>{LABELS[field]}:</b> '
                         f'<span{style}>{body}</span></span>')
        return ('<div data-testid="console-header" style="font-size:0.85em;line-height:1.45;padding:0 0.75em">'
                + "<br>".join(parts) + "</div>")

    def _on_stop(self, event: Any) -> None:
        client = client_of(event)
        who = self.core.access.name_of(client)
        self.core.stop_motion(f"STOP pressed by {who}", client)
        self._notify_all("STOP", f"{who} stopped the arm.", color="red", coalesce_s=3.0)


class ViewerLine:
    """One line at the very top of every viewer's page: who operates and how to get control.

    Each browser gets its own line (``client.gui``, above STOP); the operator's is hidden.
    Operator-only controls are drawn disabled for viewers by ``console.web.viewer_props``; this
    line says why. :meth:`refresh` re-renders every browser's line (after a change of holder).

    Args:
        server: The viser server (its connects and disconnects).
        access: The operator lock (``console.core.access.AccessControl``): who holds control
            and :meth:`~console.core.access.AccessControl.viewer_note`'s wording.
        stopped: Whether the console is shutting down (no GUI updates then).
    """

    def __init__(self, server: viser.ViserServer, access: Any, *,
                 stopped: Callable[[], bool] = lambda: False) -> None:
        self._server = server
        self._access = access
        self._stopped = stopped
        self._lock = threading.Lock()
        self._lines: dict[int, Any] = {}
        server.on_client_connect(self._on_connect)
        server.on_client_disconnect(self._on_disconnect)
        for client in list(server.get_clients().values()):
            self._on_connect(client)

    def _on_connect(self, client: viser.ClientHandle) -> None:
        with self._lock:
            if (client.client_id in self._lines or self._stopped()
                    or not connected(self._server, client)):
                return
            content, visible = self._render(client.client_id)
            self._lines[client.client_id] = client.gui.add_html(content, order=0.05,
                                                                visible=visible)
        if not connected(self._server, client):  # it left meanwhile (see events.connected)
            self._on_disconnect(client)

    def _on_disconnect(self, client: viser.ClientHandle) -> None:
        with self._lock:
            self._lines.pop(client.client_id, None)

    def _render(self, client_id: int) -> tuple[str, bool]:
        if self._access.is_operator(client_id):
            return "", False
        return ('<div data-testid="viewer-line" style="font-size:0.85em;padding:0.3em 0.75em;'
                'background:#fff3bf;border-radius:4px">'
                f"{html.escape(self._access.viewer_note())}</div>"), True

    def text(self, client_id: int) -> str:
        """The line browser ``client_id`` shows (empty for the operator and unknown browsers)."""
        with self._lock:
            line = self._lines.get(client_id)
            return "" if line is None or not line.visible else str(line.content)

    def refresh(self) -> None:
        """Re-render every browser's line (who operates, whether it is theirs to hide)."""
        with self._lock:
            if self._stopped():
                return
            for cid, line in list(self._lines.items()):
                content, visible = self._render(cid)
                try:
                    if line.content != content:
                        line.content = content
                    if line.visible != visible:
                        line.visible = visible
                except Exception:  # the client just left
                    continue
