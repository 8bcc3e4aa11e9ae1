"""Line-segments nodes of a fixed size, so a browser never holds points and colours of different lengths.

viser 1.1.1 sends a node's new ``points`` and new ``colors`` as two messages; a browser that
draws between them (they may fall in different websocket windows) draws per-vertex colours of
the wrong length, seen as white lines at random. :class:`FixedLines` keeps the number of
segments fixed (unused ones are copies of the last, drawn over it) and makes the node again,
larger, in one message when more are needed.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]


def padded(segments: Array, size: int) -> Array:
    """``segments`` (k, 2, 3), 1 <= k <= size, filled up to ``size`` with copies of the last
    one (drawn over it, so nothing shows)."""
    return np.concatenate([segments, np.repeat(segments[-1:], size - len(segments), 0)])


class FixedLines:
    """A line-segments node of a fixed number of segments in one colour: only its points
    change (a browser given new points and colours of another length in two messages may
    draw the lines white), and it is made again, larger, when a carry needs more."""

    def __init__(self, scene: Any, name: str, color: tuple[int, int, int], thickness: float,
                 size: int) -> None:
        self.scene, self.name, self.color, self.thickness = scene, name, color, thickness
        self.handle = self._make(size)

    def _make(self, size: int) -> Any:
        colors = np.broadcast_to(np.array(self.color, np.uint8), (size, 2, 3)).copy()
        return self.scene.add_line_segments(self.name, np.zeros((size, 2, 3)), colors,
                                            thickness=self.thickness, visible=False)

    def show(self, segments: Array) -> None:
        size = len(self.handle.points)
        if len(segments) > size:
            self.handle.remove()
            self.handle = self._make(max(len(segments), 2 * size))
            size = len(self.handle.points)
        self.handle.points = padded(segments, size)
        self.handle.visible = True
