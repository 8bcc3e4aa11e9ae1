"""A plan or a recorded run as one self-contained HTML file for students (no server, no net).

Both exports use viser's scene serializer (``ViserServer.get_scene_serializer().as_html()``):
the viewer's client bundle with the scene embedded as base64, opened straight from disk.

* :func:`scene_html` -- the live scene as it is now: table, arm and whatever panels drew into
  ``server.scene`` (objects, a planned path). Per-client nodes (replay ghosts) are not included.
* :func:`recording_html` -- a recorded run, animated: the console's stage and the arm
  (:func:`draw_stage`: theme, table, lights, first camera, the arm as plain meshes -- the scene
  layers themselves, no console app) are drawn into a private scene, and the arm is
  stepped through the recording's states with ``insert_sleep`` between frames, so the file plays
  back with viser's timeline. viser 1.1.1 makes a scene and its serializer only with a
  ``ViserServer``, so that scene is a private one on 127.0.0.1 (an ephemeral port no browser is
  told of, stopped again); the console's own server and its browsers never see it.
  Its markers (the log's sentences: phase changes, faults, STOP, operator actions;
  ``console.playback.replay_markers``) are a label in the scene that changes at each marker's
  time and a collapsible list beside the view (never over it). The table as the operator set it
  up -- objects, obstacles with their clearance rings, the bin -- and the plan (approach circles,
  numbered waypoints, the arm at the grasp), from the recording's ``objects`` and ``plan``
  records (:class:`console.playback.recorded_scene.RecordedScene`), are drawn as they were at
  each time, so the file shows what the operator saw.

:func:`external_urls` lists the http(s) URLs in a file, to check it needs nothing online.
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np
import viser

from console.core.model import ArmModel, model_for
from console.playback.recorded_scene import RecordedScene
from console.playback.replay_markers import current_marker, markers_of, with_markers
from console.recording.recorder import Recording
from console.scene.arm_view import ArmView
from console.scene.arm_view_factory import make_arm_view
from console.scene.stage import add_lights, add_table, setup_camera, setup_theme, table_extent
from core.robots import Robot

# Namespace identifiers inside SVG/XML are names, not resources a browser fetches.
_NAMESPACES = ("http://www.w3.org/2000/svg", "http://www.w3.org/1999/xlink",
               "http://www.w3.org/1999/xhtml", "http://www.w3.org/XML/1998/namespace")
_URL = re.compile(r"https?://[A-Za-z0-9.\-]+(?::\d+)?[^\s\"'<>)]*")


def external_urls(html: str) -> list[str]:
    """http(s) URLs in ``html`` other than XML namespace names (empty for a standalone file)."""
    return sorted({u for u in _URL.findall(html) if not u.startswith(_NAMESPACES)})


def scene_html(server: viser.ViserServer, dark_mode: bool = False) -> str:
    """The live scene of ``server`` as a standalone HTML document."""
    return server.get_scene_serializer().as_html(dark_mode=dark_mode)


def draw_overlay(scene: viser.SceneApi, data: dict[str, Any], root: str = "/overlays") -> Any:
    """Draw an ``overlay`` record (``name``, ``points`` (k, 3), ``color``) as a polyline."""
    pts = np.asarray(data.get("points", ()), dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 2 or not np.all(np.isfinite(pts)):
        return None
    name = re.sub(r"[^A-Za-z0-9_-]+", "_", str(data.get("name", "overlay")))[:40]
    color = tuple(int(c) for c in data.get("color", (200, 40, 160)))[:3]
    segments = np.stack([pts[:-1], pts[1:]], axis=1)
    return scene.add_line_segments(f"{root}/{name}", segments, color, thickness=0.004)


def draw_stage(server: viser.ViserServer, robot: Robot) -> ArmView[ArmModel]:
    """What the live console draws before any panel (``console.scene.stage``: theme, table,
    lights, first camera) and the arm as plain meshes (``"vertices"``: a file plays back
    without bone messages; no dead band: every frame given is drawn); returns the arm's view."""
    model = model_for(robot)
    theme = setup_theme(server, robot.name)
    add_table(server.scene, theme, table_extent(robot, model.kind))
    add_lights(server.scene, theme)
    setup_camera(server, robot, model.kind)
    return make_arm_view(server.scene, model, method="vertices", dead_band=None)


def recording_html(robot: Robot, rec: Recording, *, fps: float = 15.0,
                   max_frames: int = 900, dark_mode: bool = False) -> str:
    """A recorded run as a standalone, animated HTML document.

    Args:
        robot: The robot the recording is of (its kind and shape match, see load_recording).
        rec: The loaded recording.
        fps: Frames per second of the animation (fewer when the run is long).
        max_frames: Upper bound on animation frames (bounds the file size).
    """
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        view = draw_stage(server, robot)
        serializer = server.get_scene_serializer()
        duration = rec.duration
        rate = fps if duration <= 0 else min(fps, max_frames / duration)
        grid = np.arange(0.0, duration + 1e-9, 1.0 / rate) if duration > 0 else np.zeros(1)
        markers = markers_of(rec)
        grid = np.union1d(grid, [m.t for m in markers if 0.0 <= m.t <= duration])
        grid = np.union1d(grid, [e.t for e in rec.events  # the table and plan change there
                                 if e.kind in ("objects", "plan") and 0.0 <= e.t <= duration])
        label = server.scene.add_label("/markers/label", "", position=(0.0, -0.06, 0.12),
                                       visible=False)
        shown = -1
        last_q: np.ndarray | None = None
        drawn: dict[str, int] = {}
        recorded = RecordedScene(server.scene, robot)
        pending = 0.0
        prev_t = 0.0
        for t in grid:
            pending += float(t) - prev_t
            prev_t = float(t)
            q = rec.q_at(float(t))
            overlays = rec.overlays_until(float(t))
            changed_overlays = {k: v for k, v in overlays.items() if drawn.get(k) != id(v)}
            found = current_marker(markers, float(t))
            new_marker = found is not None and found[0] != shown
            new_table = recorded.changes_at(rec, float(t))
            if last_q is not None and np.array_equal(q, last_q) and not changed_overlays \
                    and not new_marker and not new_table:
                continue
            if pending > 0:
                serializer.insert_sleep(pending)
                pending = 0.0
            with server.atomic():
                recorded.show(rec, float(t))
                view.update(q)
                for name, data in changed_overlays.items():
                    draw_overlay(server.scene, data)
                    drawn[name] = id(data)
                if new_marker and found is not None:
                    shown = found[0]
                    label.text = found[1].label
                    label.visible = True
            last_q = q
        if pending > 0:
            serializer.insert_sleep(pending)
        return with_markers(serializer.as_html(dark_mode=dark_mode), markers)
    finally:
        server.stop()
