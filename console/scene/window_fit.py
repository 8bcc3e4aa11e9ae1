"""Each browser's camera framed for its own window, so the arm is in view on a tablet or a phone.

The initial camera (``console.scene.stage.setup_camera``) is one pose for every browser, made
for a wide window (1600 x 1000 with the panel docked beside the 3D view). In a tall window the
same pose cuts the arm's reach off at the sides (820 x 1180: a 500 px wide 3D view), and on a
phone viser's bottom sheet covers the lower half of the view (``console.web.phone_sheet``).
:class:`WindowFit` watches each browser's camera reports (viser sends the canvas size with
them): when the canvas's size differs from what the browser's camera was last framed for, and
the camera is still where the console put it (the person has not turned or zoomed it), it moves
that browser's camera to the first preset framed for that canvas
(``console.scene.camera.presets_for_window``). A camera the person moved stays theirs; "Reset
view" (the View panel) frames it for the window again.
"""

from __future__ import annotations

import dataclasses
import threading
from typing import Any, Callable

import numpy as np

from console.scene.camera import CameraPose, apply

POSE_TOLERANCE_M = 2e-3  # a camera within this of where it was put has not been moved


@dataclasses.dataclass
class _Framed:
    """What one browser's camera was last framed for, and where it was put."""

    size: tuple[int, int]
    pose: CameraPose


def _at(camera: Any, pose: CameraPose) -> bool:
    """Whether a browser's reported camera is (still) at ``pose``."""
    return bool(np.allclose(camera.position, pose.position, atol=POSE_TOLERANCE_M)
                and np.allclose(camera.look_at, pose.look_at, atol=POSE_TOLERANCE_M))


class WindowFit:
    """Re-frames every browser's camera for its canvas (see the module docstring).

    Args:
        server: The viser server (its connects, disconnects and clients' cameras).
        initial: The initial camera's pose (every browser starts there).
        first_for: The first preset for a canvas of (width, height) pixels.
        stopped: Whether the console is shutting down (no camera updates then).
    """

    def __init__(self, server: Any, initial: CameraPose,
                 first_for: Callable[[int, int], CameraPose], *,
                 stopped: Callable[[], bool] = lambda: False) -> None:
        self._initial = initial
        self._first_for = first_for
        self._stopped = stopped
        self._lock = threading.Lock()
        self._framed: dict[int, _Framed] = {}
        server.on_client_connect(self._on_connect)
        server.on_client_disconnect(self._on_disconnect)
        for client in list(server.get_clients().values()):
            self._on_connect(client)

    def _on_connect(self, client: Any) -> None:
        client.camera.on_update(lambda camera: self.on_camera(client, camera))

    def _on_disconnect(self, client: Any) -> None:
        with self._lock:
            self._framed.pop(client.client_id, None)

    def framed_size(self, client_id: int) -> tuple[int, int] | None:
        """The canvas size (px) a browser's camera was last framed for (None: not yet)."""
        with self._lock:
            framed = self._framed.get(client_id)
            return None if framed is None else framed.size

    def framed_pose(self, client_id: int) -> CameraPose | None:
        """Where the console last put (or found) a browser's camera (None: not framed yet)."""
        with self._lock:
            framed = self._framed.get(client_id)
            return None if framed is None else framed.pose

    def on_camera(self, client: Any, camera: Any) -> CameraPose | None:
        """A browser reported its camera: frame it for its canvas if that changed and the
        camera is where the console put it; the pose it was moved to (None: left alone)."""
        if self._stopped():
            return None
        size = (int(camera.image_width), int(camera.image_height))
        if size[0] <= 0 or size[1] <= 0:
            return None
        with self._lock:
            framed = self._framed.get(client.client_id)
            last = self._initial if framed is None else framed.pose
            if framed is not None and framed.size == size:
                return None
            if not _at(camera, last):     # the person moved it: theirs; remember the size
                self._framed[client.client_id] = _Framed(size, last)
                return None
            pose = self._first_for(*size)
            self._framed[client.client_id] = _Framed(size, pose)
        if _at(camera, pose):
            return None
        with client.atomic():
            apply(client.camera, pose)
        return pose
