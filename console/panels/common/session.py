"""Session panel: take/release control, record, replay, export (STOP is the header's).

Shared widgets (every browser sees the same): who holds control (shown in the header,
``console.panels.common.header``), recording start/stop (operator only) and "Export scene (HTML)" (anyone: a
plan to hand to students).

Per-browser widgets (``client.gui``, added inside this panel's folder, so what one browser types
is never shown to another -- the operator token least of all): the user's role, name, the token
field, Take control / Release control, and the replay section (``console.playback.replay``).
They are built by the panel's own thread once a browser has stayed ``BUILD_AFTER_S``, a batch
at a time with one refresh of the role lines: a socket that connects and leaves at once (a
connection flood: 1000 in 8 s) costs no widgets, and their allocations no longer spread over
memory the process then keeps (issue 32).
"""

from __future__ import annotations

import html
import logging
import threading
import time
from typing import Any

import viser

from console.core.access import NotOperator
from console.core.operator import Operator
from console.playback.export import scene_html
from console.panels.common.base import Panel, operator_only
from console.panels.common.events import connected
from console.playback.replay import ReplayPlayer, ReplaySession

log = logging.getLogger(__name__)

BUILD_AFTER_S = 0.2  # s a browser stays before its own widgets are built (a flood: 0.5 s, the same)


class _ClientWidgets:
    """The per-browser widgets of one client."""

    def __init__(self, role: Any, name: Any, token: Any, take: Any, release: Any) -> None:
        self.role, self.name, self.token, self.take, self.release = role, name, token, take, release


class SessionPanel(Panel):
    """Control lock, STOP, recording, replay and export (see the module docstring)."""

    title = "Session"
    tab = "Session"
    order = 1.0

    def build(self) -> None:
        gui = self.gui
        self._lock = threading.Lock()
        # viser runs connect callbacks concurrently, and a folder handle can be entered by one
        # thread at a time: per-client widgets are built one client after the other.
        self._build_lock = threading.Lock()
        self.clients: dict[int, _ClientWidgets] = {}
        self.clock = time.monotonic  # when browsers are due (tests move it by hand)
        self._pending: dict[int, tuple[float, viser.ClientHandle]] = {}  # id -> (due, client)
        self._wake = threading.Event()
        self._quit = threading.Event()
        self._builder: threading.Thread | None = None  # started by after_build
        self.player = ReplayPlayer()
        self.demo_btn = None
        if self.app.services.demo is not None:
            self.demo_btn = gui.add_button("Run demo motion", order=20.0,
                                           hint="A slow looping motion (STOP ends it).")
            self.demo_btn.on_click(self._on_demo)
        self.rec_name = gui.add_text("Recording name", "", order=30.0,
                                     hint="Optional; letters, digits, - and _ are kept.")
        self.rec_btn = gui.add_button("Start recording", order=31.0, icon=viser.Icon.PLAYER_RECORD)
        self.rec_btn.on_click(self._on_record)
        self.export_btn = gui.add_button("Export scene (HTML)", order=40.0,
                                         hint="The 3D scene as one file that opens offline.")
        self.export_btn.on_click(self._on_export_scene)
        self.allow_viewers(self.export_btn)  # STOP is the header's; the rest: operator
        self.app.access.add_listener(self._on_control_change)
        self.app.server.on_client_connect(self._on_connect)
        self.app.server.on_client_disconnect(self._on_disconnect)
        self.refresh()

    def after_build(self) -> None:
        built = [self._build_now(client)  # browsers that connected before the panels were built
                 for client in list(self.app.server.get_clients().values())]
        if any(built):
            self.refresh()
        self._builder = threading.Thread(target=self._builder_loop, name="session-widgets",
                                         daemon=True)
        self._builder.start()

    # -- per-client widgets ------------------------------------------------------------------

    def _on_connect(self, client: viser.ClientHandle) -> None:
        """(viser's thread pool) Due in BUILD_AFTER_S, if it stays."""
        with self._lock:
            self._pending[client.client_id] = (self.clock() + BUILD_AFTER_S, client)
        self._wake.set()

    def _builder_loop(self) -> None:
        wait: float | None = None
        while not self._quit.is_set():
            self._wake.wait(wait)
            self._wake.clear()
            if self._quit.is_set():
                return
            try:
                due = self.build_due(self.clock())
            except Exception:  # (the role lines' refresh) must not end the thread
                log.exception("refreshing the Session panel failed")
                due = self.clock() + BUILD_AFTER_S  # those still waiting: look again
            wait = None if due is None else max(0.01, due - self.clock())

    def build_due(self, now: float) -> float | None:
        """Build the widgets of the browsers due by ``now`` that are still connected, refresh
        the role lines once for them; when the next browser is due (None: none waits)."""
        with self._lock:
            due = [client for at, client in self._pending.values() if at <= now]
            for client in due:
                del self._pending[client.client_id]
            later = min((at for at, _ in self._pending.values()), default=None)
        built = False
        for client in due:
            try:
                built = self._build_now(client) or built
            except Exception:  # one browser's widgets must not cost the others theirs
                log.exception("building the Session widgets of browser %s failed",
                              client.client_id)
        if built:
            self.refresh()
        return later

    def _build_now(self, client: viser.ClientHandle) -> bool:
        """Build ``client``'s widgets unless built or gone; whether it built them."""
        # (only after build(), which runs inside the folder's `with` block that _build_client
        # enters too: after_build calls it, and the builder thread starts there)
        server = self.app.server
        with self._build_lock:
            if client.client_id in self.clients or not connected(server, client):
                return False  # already built, or gone
            try:
                self._build_client(client, self.app.access)
            except KeyError:  # viser removed the browser's containers: it left mid-build
                if connected(server, client):
                    raise
            if not connected(server, client):  # it left meanwhile: its disconnect callback
                self._on_disconnect(client)  # may have found nothing yet to drop
                return False
        return True

    def _build_client(self, client: viser.ClientHandle, access: Any) -> None:
        gui = client.gui
        with self.folder:
            role = gui.add_html("", order=2.0)
            name = gui.add_text("Your name", access.name_of(client), order=3.0,
                                hint="Shown to everyone when you hold control.")
            token = None
            if access.needs_token:
                token = gui.add_text("Operator token", "", order=4.0,
                                     hint="Printed in the terminal where serve.py runs.")
            take = gui.add_button("Take control", order=5.0, icon=viser.Icon.LOCK)
            release = gui.add_button("Release control", order=6.0, icon=viser.Icon.LOCK_OPEN)
            replay = ReplaySession(self.app, client, order=50.0)
        widgets = _ClientWidgets(role, name, token, take, release)
        name.on_update(lambda e: self._on_name(client, widgets))
        take.on_click(lambda e: self._on_take(client, widgets))
        release.on_click(lambda e: self._on_release(client))
        with self._lock:
            self.clients[client.client_id] = widgets
        self.player.add(client.client_id, replay)

    def _on_disconnect(self, client: viser.ClientHandle) -> None:
        with self._lock:
            self._pending.pop(client.client_id, None)
            self.clients.pop(client.client_id, None)
        self.player.remove(client.client_id)
        self.refresh()

    def _on_name(self, client: viser.ClientHandle, w: _ClientWidgets) -> None:
        self.app.access.set_name(client, str(w.name.value))
        self.refresh()

    def _on_take(self, client: viser.ClientHandle, w: _ClientWidgets) -> None:
        token = None if w.token is None else str(w.token.value)
        try:
            op = self.app.access.take(client, token, str(w.name.value),
                                      address=self.app.guard.address_of(client))
        except NotOperator as exc:
            self.app.refuse(client, exc, "take control")
            return
        if w.token is not None:
            w.token.value = ""
        client.add_notification("You have control", f"You are the operator, {op.name}. "
                                "Keep this tab open: closing it stops the arm.",
                                color="green", auto_close_seconds=6.0)

    def _on_release(self, client: viser.ClientHandle) -> None:
        if not self.app.access.release(client):
            client.add_notification("Not the operator", "You do not hold control.",
                                    auto_close_seconds=5.0)

    def _on_control_change(self, new: Operator | None, previous: Operator | None,
                           reason: str) -> None:
        if new is not None:
            self.app.notify_all("Control", f"{reason}.", color="blue", coalesce_s=3.0)
        self.refresh()

    # -- shared actions ----------------------------------------------------------------------

    @operator_only(action="run the demo motion")
    def _on_demo(self, event: viser.GuiEvent) -> None:
        demo = self.app.services.demo
        if demo is None:  # (the button exists only with a demo)
            return
        self.app.recorder.action("started the demo motion", event.client)
        self.app.core.start_motion(demo.start)

    @operator_only(action="start or stop a recording")
    def _on_record(self, event: viser.GuiEvent) -> None:
        rec = self.app.recorder
        if rec.recording:
            path = rec.stop()
            self.rec_btn.label = "Start recording"
            if event.client is not None and path is not None:
                event.client.add_notification("Recording saved", path.name,
                                              auto_close_seconds=6.0)
            for session in self.player.all():
                session.refresh_files()
        else:
            path = rec.start(str(self.rec_name.value), event.client)
            self.rec_btn.label = "Stop recording"
            rec.action("started recording", event.client)
        self.refresh()

    def _on_export_scene(self, event: viser.GuiEvent) -> None:
        client = event.client
        if client is None:
            return
        data = self.app.data
        name = data.new_name("exports", "scene", ".html")
        path = data.path("exports", name, ".html")
        page = scene_html(self.app.server)
        path.write_text(page, encoding="utf-8")
        self.app.recorder.action(f"exported the scene as {name}", client)
        client.send_file_download(name, page.encode("utf-8"))

    # -- display -----------------------------------------------------------------------------

    def refresh(self) -> None:
        """Re-render the shared status and every browser's role line."""
        if self.app.stopped:  # shutting down: the connections are closing
            return
        access = self.app.access
        holder = access.holder
        with self._lock:
            clients = dict(self.clients)
        if holder is None:
            who = "nobody — take control in the Session tab"
        else:
            since = time.strftime("%H:%M:%S", time.localtime(holder.since))
            who = f"{html.escape(holder.name)} (since {since})"
        rec = self.app.recorder
        recording = (f' · <span data-testid="recording">● recording {rec.path.name}</span>'
                     if rec.recording and rec.path is not None else "")
        self.app.header.show(
            "control", f'<span data-testid="control-status"><span data-testid="holder">{who}'
            f'</span> · {len(clients)} browser{"s" if len(clients) != 1 else ""}{recording}'
            "</span>", escape=False)
        connected = self.app.server.get_clients()
        for cid, w in clients.items():
            if cid not in connected:
                continue
            is_op = holder is not None and holder.client_id == cid
            role = "operator" if is_op else "viewer"
            text = ("You hold control: only you can move the arm." if is_op else
                    "You are watching; STOP, replay and export work for you too.")
            try:
                w.role.content = (f'<div data-testid="role" data-role="{role}"><b>You:</b> '
                                  f'{role} — {text}</div>')
            except Exception:  # the client just left
                log.debug("role update for client %s failed", cid)

    def close(self) -> None:
        self._quit.set()
        self._wake.set()
        if self._builder is not None and self._builder is not threading.current_thread():
            self._builder.join(2.0)
        self.player.stop()
        super().close()
