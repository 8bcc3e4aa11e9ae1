"""Per-browser replay of a recording: the run as it was, in a scene only that browser sees.

Each connected client gets a :class:`ReplaySession` with its own (client-scoped) widgets --
recording picker (the newest recording first and picked), Load, Play/Pause, timeline slider
(seek), speed, the log -- and, once a recording is loaded, its own scene under ``/replay`` in
``client.scene``: a translucent ghost arm at the recorded configuration, and the table and plan
as they were recorded at that time (objects, obstacles, bin, approach circles, numbered
waypoints: :class:`console.playback.recorded_scene.RecordedScene`). The log shows what happened
up to that time as sentences with times ("12.4 s  Armed", "30.1 s  Phase: approach → grasp":
:mod:`console.playback.replay_log`). Replaying never commands the arm and never changes what
other browsers see, so a viewer may replay freely. One :class:`ReplayPlayer` thread advances
every playing session.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Protocol

import viser

from console.core.model import ArmModel
from console.scene.arm_view import ArmView
from console.scene.arm_view_factory import make_arm_view
from console.core.datadir import BadFileName, DataDir
from console.playback.export import draw_overlay, recording_html
from console.playback.recorded_scene import RecordedScene
from console.recording.recorder import SUFFIXES, Recorder, Recording, load_recording
from console.playback.replay_markers import (COLORS, Marker, current_marker, markers_of,
                                             next_marker, previous_marker)
from core.robots import Robot
from console.web.widgets import set_slider_marks

log = logging.getLogger(__name__)
GHOST_COLOR = (150, 150, 160)
GHOST_OPACITY = 0.55
SPEEDS = ("0.25x", "0.5x", "1x", "2x", "4x")
NONE = "(no recordings yet)"
LOG_LINES = 8  # the log shows this many sentences up to the replay's time


class ReplayHost(Protocol):
    """What a replay reads of the console (``console.app.ConsoleApp`` is one): where the
    recordings are, the arm they are of, and the recorder that logs an export."""

    @property
    def data(self) -> DataDir: ...

    @property
    def model(self) -> ArmModel: ...

    @property
    def robot(self) -> Robot: ...

    @property
    def recorder(self) -> Recorder: ...


class ReplaySession:
    """One client's replay widgets, ghost arm and play position."""

    def __init__(self, app: ReplayHost, client: viser.ClientHandle, order: float) -> None:
        self.app = app
        self.client = client
        self.rec: Recording | None = None
        self.ghost: ArmView[ArmModel] | None = None
        self.pos = 0.0
        self.playing = False
        self.speed = 1.0
        self.markers: list[Marker] = []
        self.recorded = RecordedScene(client.scene, app.robot, "/replay/recorded")
        self._lock = threading.RLock()  # advance() draws under it
        gui = client.gui
        self.folder = gui.add_folder("Replay", order=order, expand_by_default=False)
        with self.folder:
            self.files = gui.add_dropdown("Recording", self._file_options())
            self.load_btn = gui.add_button("Load recording")
            self.play_btn = gui.add_button("Play replay", disabled=True)
            self.timeline = gui.add_slider("Time (s)", min=0.0, max=1.0, step=0.05,
                                           initial_value=0.0, disabled=True)
            self.prev_btn = gui.add_button("◀ Previous marker", disabled=True,
                                           hint="Phase change, fault, STOP or operator action")
            self.next_btn = gui.add_button("Next marker ▶", disabled=True,
                                           hint="Phase change, fault, STOP or operator action")
            self.speed_dd = gui.add_dropdown("Speed", SPEEDS, initial_value="1x")
            self.info = gui.add_html('<small data-testid="replay-info">nothing loaded</small>')
            self.export_btn = gui.add_button("Export run (HTML)", disabled=True,
                                             hint="One file that plays this run offline.")
        self._loading = False
        self.load_btn.on_click(lambda e: self.load_in_background(self.files.value))
        self.play_btn.on_click(lambda e: self.toggle())
        self.timeline.on_update(self._on_seek)
        self.speed_dd.on_update(self._on_speed)
        self.prev_btn.on_click(lambda e: self.jump(-1))
        self.next_btn.on_click(lambda e: self.jump(+1))
        self.export_btn.on_click(lambda e: self.export())

    def _file_options(self) -> tuple[str, ...]:
        """The recordings (both formats), newest first."""
        folder = self.app.data.folder("recordings")
        found: list[tuple[float, str]] = []
        for suffix in SUFFIXES:
            for name in self.app.data.list("recordings", suffix):
                try:
                    found.append((folder.joinpath(name).stat().st_mtime, name))
                except OSError:  # deleted meanwhile
                    continue
        found.sort(key=lambda f: f[0], reverse=True)
        return tuple(n for _, n in found) if found else (NONE,)

    def refresh_files(self) -> None:
        """Re-read the recordings; a new one (just saved) becomes the picked one."""
        before = set(self.files.options)
        options = self._file_options()
        self.files.options = options
        if any(n not in before for n in options) and options[0] != NONE:
            self.files.value = options[0]

    def _tell(self, title: str, body: str, color: str = "blue") -> None:
        self.client.add_notification(title, body, color=color, auto_close_seconds=8.0)

    def load_in_background(self, name: str) -> threading.Thread | None:
        """:meth:`load` in a thread of its own, so a big file never holds up the callbacks
        (one load per browser at a time; None when one is already running)."""
        with self._lock:
            if self._loading:
                self._tell("Still loading", "The previous recording is still being read.")
                return None
            self._loading = True
        self.info.content = f'<small data-testid="replay-info">loading {_escape(name)}…</small>'

        def run() -> None:
            try:
                self.load(name)
            finally:
                self._loading = False
        t = threading.Thread(target=run, name="replay-load", daemon=True)
        t.start()
        return t

    def load(self, name: str) -> bool:
        """Load recording ``name`` (a file in the data folder's recordings); False on refusal."""
        if name == NONE:
            self._tell("Nothing to load", "No recordings yet: the operator records with "
                       "'Start recording'.")
            return False
        try:
            suffix = next((s for s in SUFFIXES if isinstance(name, str) and name.endswith(s)),
                          SUFFIXES[0])
            path = self.app.data.path("recordings", name, suffix)
            if not path.is_file():
                raise BadFileName(f"no recording named {name!r}")
            rec = load_recording(path, self.app.model)
        except ValueError as exc:  # BadFileName is a ValueError too
            self._tell("Cannot load recording", str(exc), "red")
            return False
        except Exception as exc:  # noqa: BLE001 - whatever went wrong, the browser hears it
            log.exception("loading recording %s failed", name)
            self._tell("Cannot load recording", f"{name}: {type(exc).__name__}: {exc}", "red")
            return False
        with self._lock:
            self.rec, self.pos, self.playing = rec, 0.0, False
            self.recorded.clear()
            if self.ghost is None:
                self.ghost = make_arm_view(self.client.scene, self.app.model, root="/replay",
                                           method="vertices", dead_band=None)  # one browser:
                # a seek draws exactly the recorded configuration
                for handle in vars(self.ghost).values():
                    if hasattr(handle, "opacity") and hasattr(handle, "color"):
                        handle.color = GHOST_COLOR
                        handle.opacity = GHOST_OPACITY
            self.timeline.max = max(rec.duration, 0.05)
            self.markers = markers_of(rec)
            set_slider_marks(self.timeline, (round(m.t, 3) for m in self.markers[:200]))
            self.prev_btn.disabled = self.next_btn.disabled = not self.markers
            self.timeline.disabled = False
            self.play_btn.disabled = False
            self.export_btn.disabled = False
            self.play_btn.label = "Play replay"
        self.draw()
        return True

    def toggle(self) -> None:
        with self._lock:
            if self.rec is None:
                return
            if not self.playing and self.pos >= self.rec.duration:
                self.pos = 0.0
            self.playing = not self.playing
            self.play_btn.label = "Pause replay" if self.playing else "Play replay"

    def seek(self, t: float) -> None:
        with self._lock:
            if self.rec is None:
                return
            self.pos = min(max(float(t), 0.0), self.rec.duration)
        self.draw(move_slider=False)

    def jump(self, direction: int) -> Marker | None:
        """Seek to the next (``direction`` > 0) or previous marker; returns it (or None)."""
        with self._lock:
            if self.rec is None:
                return None
            pick = next_marker if direction > 0 else previous_marker
            marker = pick(self.markers, self.pos)
            if marker is None:
                return None
            self.pos, self.playing = min(marker.t, self.rec.duration), False
            self.play_btn.label = "Play replay"
        self.draw()
        return marker

    def _on_seek(self, event: viser.GuiEvent) -> None:
        if event.client is not None:
            self.seek(self.timeline.value)

    def _on_speed(self, event: viser.GuiEvent) -> None:
        value = str(self.speed_dd.value)
        self.speed = float(value.rstrip("x")) if value in SPEEDS else 1.0

    def advance(self, dt: float) -> None:
        """Move the replay on by ``dt`` s of wall time (at its speed) and draw it; at the end the
        last pose is drawn before ``playing`` turns False, so whoever reads it stopped sees the
        arm at the end."""
        with self._lock:
            if self.rec is None or not self.playing:
                return
            self.pos += dt * self.speed
            ended = self.pos >= self.rec.duration
            if ended:
                self.pos = self.rec.duration
            self.draw()
            if ended:
                self.playing = False
                self.play_btn.label = "Play replay"
                self.draw(move_slider=False)  # the info line says "paused"

    def draw(self, move_slider: bool = True) -> None:
        with self._lock:
            rec, ghost, pos = self.rec, self.ghost, self.pos
            if rec is None or ghost is None:
                return
            with self.client.atomic():
                ghost.update(rec.q_at(pos))
                for data in rec.overlays_until(pos).values():
                    draw_overlay(self.client.scene, data, root="/replay/overlays")
                self.recorded.show(rec, pos)  # the table and plan as recorded then
                if move_slider:
                    self.timeline.value = round(pos, 3)
                found = current_marker(self.markers, pos)
                marker = "" if found is None else (
                    f'<br><small data-testid="replay-marker" data-index="{found[0]}" '
                    f'style="color:{COLORS[found[1].category]}">marker {found[0] + 1}/'
                    f"{len(self.markers)}: {_escape(found[1].label)}</small>")
                self.info.content = (
                    f'<small data-testid="replay-info" data-t="{pos:.3f}">{rec.name} · '
                    f"{pos:.1f} / {rec.duration:.1f} s · "
                    f"{'playing' if self.playing else 'paused'} {self.speed:g}x</small>"
                    f'<br><small data-testid="replay-legend">In 3D, for you only: the '
                    f"translucent grey arm with the objects, bin and plan as recorded at "
                    f"{pos:.1f} s, drawn over the live arm and table</small>"
                    + marker + log_html(self.markers, pos))

    def export(self) -> None:
        rec = self.rec
        if rec is None:
            return
        self._tell("Exporting", f"Building {rec.name} as HTML…")
        try:
            html = recording_html(self.app.robot, rec)
        except Exception as exc:  # report, never crash the callback pool
            log.exception("export of %s failed", rec.name)
            self._tell("Export failed", str(exc), "red")
            return
        stem = next((rec.name.removesuffix(s) for s in SUFFIXES if rec.name.endswith(s)),
                    rec.name)
        name = self.app.data.new_name("exports", stem, ".html")
        path = self.app.data.path("exports", name, ".html")
        path.write_text(html, encoding="utf-8")
        self.app.recorder.action(f"exported run {rec.name} as {name}", self.client)
        self.client.send_file_download(name, html.encode("utf-8"))

    def close(self) -> None:
        with self._lock:
            self.playing = False
            self.rec = None


def _escape(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def log_html(markers: list[Marker], t: float, k: int = LOG_LINES) -> str:
    """The last ``k`` log sentences at or before ``t``, one line each ("12.4 s  Armed"; the
    newest in bold), or a line saying nothing happened yet."""
    found = current_marker(markers, t)
    if found is None:
        return '<div data-testid="replay-log"><small>Log: nothing yet.</small></div>'
    end = found[0] + 1
    rows = []
    for i in range(max(0, end - k), end):
        m = markers[i]
        weight = "font-weight:600;" if i == end - 1 else ""
        rows.append(f'<div data-t="{m.t:.3f}" data-category="{m.category}" '
                    f'style="white-space:pre-wrap;{weight}color:{COLORS[m.category]}">'
                    f"<small>{_escape(m.label)}</small></div>")
    return '<div data-testid="replay-log">' + "".join(rows) + "</div>"


class ReplayPlayer:
    """Advances every playing :class:`ReplaySession` at ``rate_hz`` from one thread, which runs
    while any browser has a session (it ends when the last one left)."""

    def __init__(self, rate_hz: float = 20.0) -> None:
        self.period = 1.0 / rate_hz
        self.sessions: dict[int, ReplaySession] = {}
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()

    def add(self, client_id: int, session: ReplaySession) -> None:
        with self._lock:
            self.sessions[client_id] = session
            if self._thread is None or not self._thread.is_alive():
                self._stop.clear()
                self._thread = threading.Thread(target=self._run, name="console-replay",
                                                daemon=True)
                self._thread.start()

    def remove(self, client_id: int) -> None:
        with self._lock:
            session = self.sessions.pop(client_id, None)
        if session is not None:
            session.close()

    def all(self) -> list[ReplaySession]:
        with self._lock:
            return list(self.sessions.values())

    def stop(self) -> None:
        self._stop.set()

    def _run(self) -> None:
        last = time.perf_counter()
        while not self._stop.wait(self.period):
            with self._lock:
                if not self.sessions:  # every browser left: the next add starts one again
                    self._thread = None
                    return
            now = time.perf_counter()
            dt, last = now - last, now
            for session in self.all():
                if session.playing:
                    try:
                        session.advance(dt)
                    except Exception:  # a client that just left
                        log.debug("replay advance failed", exc_info=True)

    def __len__(self) -> int:
        return len(self.sessions)
