"""Line-segments nodes of a fixed size, so a browser never holds points and colours of different lengths.

viser 1.1.1 sends a node's new ``points`` and new ``colors`` as two messages; a browser that
draws between them (they may fall in different websocket windows) draws per-vertex colours of
the wrong length, seen as white lines at random. :class:`FixedLines` keeps the number of
segments fixed (unused ones are copies of the last, drawn over it) and makes the node again,
larger, when more are needed (its create message carries points and colours together).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]


def padded(segments: npt.NDArray[Any], size: int) -> npt.NDArray[Any]:
    """``segments`` (k, 2, 3), 1 <= k <= size, filled up to ``size`` with copies of the last
    one (drawn over it, so nothing shows); the same for their colours."""
    return np.concatenate([segments, np.repeat(segments[-1:], size - len(segments), 0)])


class FixedLines:
    """A line-segments node of a fixed number of segments: its points and colours always have
    that length (a browser given new points and colours of another length in two messages may
    draw the lines white), and it is made again, larger, when more are needed.

    Args:
        scene: The viser scene (``server.scene``).
        name: The node's name.
        color: Its colour where :meth:`show` is given none.
        thickness: Line thickness, m.
        size: Segments to begin with.
    """

    def __init__(self, scene: Any, name: str, color: tuple[int, int, int], thickness: float,
                 size: int) -> None:
        self.scene, self.name, self.color, self.thickness = scene, name, color, thickness
        self.handle = self._make(np.zeros((size, 2, 3)), self._one_color(size))

    def _one_color(self, n: int) -> npt.NDArray[np.uint8]:
        return np.broadcast_to(np.array(self.color, np.uint8), (n, 2, 3))

    def _make(self, points: Array, colors: npt.NDArray[np.uint8]) -> Any:
        return self.scene.add_line_segments(self.name, points, colors,
                                            thickness=self.thickness, visible=False)

    def show(self, segments: Array, colors: npt.ArrayLike | None = None) -> None:
        """Draw ``segments`` (k, 2, 3), k >= 1, in ``colors`` (k, 2, 3) (None: the node's
        colour); colours are sent only when they change."""
        segments = np.asarray(segments, float)
        colors = (self._one_color(len(segments)) if colors is None
                  else np.asarray(colors, np.uint8))
        size = len(self.handle.points)
        if len(segments) > size:
            self.handle.remove()
            size = max(len(segments), 2 * size)
            self.handle = self._make(padded(segments, size), padded(colors, size))
        else:
            self.handle.points = padded(segments, size)
            colors = padded(colors, size)
            if not np.array_equal(self.handle.colors, colors):
                self.handle.colors = colors
        self.handle.visible = True

    def hide(self) -> None:
        self.handle.visible = False
