"""Each browser's camera framed for its own window and for what is planned, so the arm and the
plan are in view on a desk, a tablet or a phone.

The initial camera (``console.scene.stage.setup_camera``) is one pose for every browser, made
for a wide window (1600 x 1000 with the panel docked beside the 3D view). In a tall window the
same pose cuts the arm's reach off at the sides (820 x 1180: a 500 px wide 3D view), and on a
phone viser's bottom sheet covers the lower half of the view (``console.web.phone_sheet``).
:class:`WindowFit` watches each browser's camera reports (viser sends the canvas size with
them): when the canvas's size differs from what the browser's camera was last framed for, and
the camera is still where the console put it (the person has not turned or zoomed it), it moves
that browser's camera to its preset framed for that canvas
(``console.scene.camera.presets_for_window``: the first one, or the one the person last chose
in the View panel). The presets also show what the operator plans (the soft arm's objects, bin,
approach circles and waypoints: ``console.scene.plan_frame``): when that changes the console
calls :meth:`WindowFit.refit`, which re-frames every camera still where the console put it
(a far object's plan widens the view; nothing moves while everything is already in view). A
camera the person moved stays theirs; a View preset or "Reset view" (:meth:`WindowFit.put`)
makes it the console's again. A report still carrying a pose the console put before the
newest (a quick resize: the browser's next canvas size arrives before the newest pose reached
it) is the console's camera too. The extensible arm's views are re-framed by :meth:`WindowFit.refit`
when the arm grows out of the height they were framed for (``ConsoleApp.follow_arm``).
"""

from __future__ import annotations

import dataclasses
import threading
from typing import Any, Callable, Sequence

import numpy as np

from console.scene.camera import CameraPose, apply, pick

POSE_TOLERANCE_M = 2e-3  # a camera within this of where it was put has not been moved
IN_FLIGHT = 3  # earlier poses put that a browser's reports may still carry (a quick resize)

Presets = Callable[[int, int], Sequence[CameraPose]]


@dataclasses.dataclass
class _Framed:
    """What one browser's camera was last framed for (canvas size, preset), and where it was
    put."""

    size: tuple[int, int]
    pose: CameraPose
    name: str | None = None  # the preset chosen (None: the first)
    # The poses put before ``pose``, newest first: a browser resized quickly (a tablet turned,
    # viser switching to its phone layout) reports its next canvas size before the last pose
    # put has reached it, so such a report is at one of these, and the camera is still the
    # console's (taken for the person's, a phone was left at a pose framed for a transient
    # 70 px wide canvas).
    before: tuple[CameraPose, ...] = ()

    def then(self, size: tuple[int, int], pose: CameraPose, name: str | None) -> _Framed:
        """The record after putting ``pose`` for ``size``: this pose joins :attr:`before`."""
        if pose == self.pose:
            return _Framed(size, pose, name, self.before)
        return _Framed(size, pose, name, ((self.pose,) + self.before)[:IN_FLIGHT])

    def put_by_console(self, camera: Any) -> bool:
        """Whether a reported camera is at :attr:`pose` or at a pose put before it."""
        return any(_at(camera, p) for p in (self.pose, *self.before))


def _at(camera: Any, pose: CameraPose) -> bool:
    """Whether a browser's reported camera is (still) at ``pose``."""
    return bool(np.allclose(camera.position, pose.position, atol=POSE_TOLERANCE_M)
                and np.allclose(camera.look_at, pose.look_at, atol=POSE_TOLERANCE_M))


def _still_at(client: Any, pose: CameraPose) -> bool:
    """Whether a browser's camera (as it last reported or was set) is at ``pose``."""
    try:
        return _at(client.camera, pose)
    except AssertionError:  # viser: no camera message yet
        return False


def _still_put(client: Any, framed: _Framed) -> bool:
    """Whether a browser's camera is (still) at a pose the console put (:class:`_Framed`)."""
    try:
        return framed.put_by_console(client.camera)
    except AssertionError:  # viser: no camera message yet
        return False


def _size(camera: Any) -> tuple[int, int]:
    """The canvas size (px) a browser's camera reported ((0, 0): none yet)."""
    try:
        return int(camera.image_width), int(camera.image_height)
    except (AssertionError, AttributeError, TypeError, ValueError):  # no camera message yet
        return 0, 0


class WindowFit:
    """Re-frames every browser's camera for its canvas and the plan (see the module docstring).

    Args:
        server: The viser server (its connects, disconnects and clients' cameras).
        initial: The initial camera's pose (every browser starts there).
        presets_for: The presets for a canvas of (width, height) pixels ((0, 0): not known),
            framing what is planned now; the first is the default.
        stopped: Whether the console is shutting down (no camera updates then).
    """

    def __init__(self, server: Any, initial: CameraPose, presets_for: Presets, *,
                 stopped: Callable[[], bool] = lambda: False) -> None:
        self._server = server
        self._initial = initial
        self._presets_for = presets_for
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

    def _preset(self, size: tuple[int, int], name: str | None) -> CameraPose:
        poses = self._presets_for(*size)
        return poses[0] if name is None else pick(poses, name)

    def pose_for(self, client: Any, name: str | None = None) -> CameraPose:
        """The preset ``name`` (None: the first) framed for ``client``'s window and the plan."""
        return self._preset(_size(client.camera), name)

    def put(self, client: Any, name: str | None = None) -> CameraPose:
        """Move ``client``'s camera (theirs only) to the preset ``name`` (None: the first, "Reset
        view"), framed for its window and the plan; the console re-frames it from now on (a
        new plan, a new window size) until the person moves it."""
        size = _size(client.camera)
        with self._lock:
            pose = self._preset(size, name)
            framed = self._framed.get(client.client_id)
            self._framed[client.client_id] = (_Framed(size, pose, name) if framed is None
                                              else framed.then(size, pose, name))
        with client.atomic():
            apply(client.camera, pose)
        return pose

    def on_camera(self, client: Any, camera: Any) -> CameraPose | None:
        """A browser reported its camera: frame it for its canvas if that changed and the
        camera is where the console put it; put the newest pose again when a report for the
        same canvas is at a pose the console put before it (the newest did not stick: seen
        after a quick resize, the camera left at a pose framed for a canvas 27 px wider and
        the far plan's circle cut off); the pose it was moved to (None: left alone)."""
        if self._stopped():
            return None
        size = (int(camera.image_width), int(camera.image_height))
        if size[0] <= 0 or size[1] <= 0:
            return None
        with self._lock:
            framed = self._framed.get(client.client_id) or _Framed((0, 0), self._initial)
            if not framed.put_by_console(camera):
                # The person moved it (theirs), or a pose the console put is half applied
                # (viser sets the position, then the look-at): the record stays as it is, so
                # a report at the console's pose for another canvas is framed for it (the size
                # recorded here with the old pose left a page turned from phone to tablet
                # during a refit at the phone's framing, counted as the tablet's).
                return None
            if framed.size == size:
                pose = framed.pose             # at it (nothing to do), or at one put before
            else:
                pose = self._preset(size, framed.name)
                self._framed[client.client_id] = framed.then(size, pose, framed.name)
        if _at(camera, pose):
            return None
        with client.atomic():
            apply(client.camera, pose)
        return pose

    def refit(self) -> list[int]:
        """What is planned changed: re-frame every browser's camera that is still where the
        console put it (for its window and preset); the ids of the browsers moved."""
        if self._stopped():
            return []
        moved: list[tuple[Any, CameraPose]] = []
        clients = list(self._server.get_clients().values())
        with self._lock:
            for client in clients:
                framed = self._framed.get(client.client_id)
                if framed is None or not _still_put(client, framed):
                    continue          # not framed yet, or the person's camera
                pose = self._preset(framed.size, framed.name)
                if _still_at(client, pose):
                    continue
                self._framed[client.client_id] = framed.then(framed.size, pose, framed.name)
                moved.append((client, pose))
        for client, pose in moved:
            with client.atomic():
                apply(client.camera, pose)
        return [client.client_id for client, _ in moved]
