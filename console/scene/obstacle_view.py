"""Obstacles in the 3D view, drawn so nobody mistakes them for objects to grasp.

An obstacle is a dark grey cylinder, taller than the objects, with red hatching on its top and
a red ring on the table at its radius plus the planner's clearance (where no arm point may
go); the selected obstacle's ring is thicker. The geometry is pure (:func:`hatch_segments`,
:func:`obstacle_geometry`) and tested without a server; :class:`ObstacleLayer` owns the scene
nodes and is drawn by the grasp layers only (``console.scene.grasp_layers``, like ``PlanScene``).
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
import numpy.typing as npt
import viser

from console.scene.plan_view import circle_segments, object_mesh
from core.planning.obstacles import Obstacle

Array = npt.NDArray[np.float64]
OBSTACLE_COLOR = (70, 72, 78)          # dark grey body
HATCH_COLOR = (215, 40, 40)            # red hatching on top
RING_COLOR = (215, 40, 40)             # clearance ring on the table
OBSTACLE_HEIGHT = 0.06                 # m, taller than objects (0.04 m)
HATCH_SPACING = 0.008                  # m between hatch lines
RING_Z = 0.0015


def hatch_segments(x: float, y: float, r: float, z: float,
                   spacing: float = HATCH_SPACING) -> Array:
    """Diagonal (45 deg) hatch lines clipped to the disk (x, y, r) at height z: (k, 2, 3)."""
    offsets = np.arange(-r + spacing / 2, r, spacing)
    half = np.sqrt(np.maximum(r * r - offsets * offsets, 0.0))
    d = np.array([np.sqrt(0.5), np.sqrt(0.5)])          # along the hatch
    n = np.array([-np.sqrt(0.5), np.sqrt(0.5)])         # across it
    c = np.array([x, y])
    a = c + offsets[:, None] * n - half[:, None] * d
    b = c + offsets[:, None] * n + half[:, None] * d
    seg = np.stack([a, b], 1)
    return np.concatenate([seg, np.full(seg.shape[:2] + (1,), z)], -1)


def obstacle_geometry(obstacles: Sequence[Obstacle], clearance: float) -> dict[str, Any]:
    """Hatch lines on the obstacles' tops and their clearance rings (line segments)."""
    z = OBSTACLE_HEIGHT + 0.001
    hatch = [hatch_segments(o.x, o.y, o.r, z) for o in obstacles]
    rings = [circle_segments((o.x, o.y), [o.r + clearance], RING_Z) for o in obstacles]
    empty = np.zeros((0, 2, 3))
    return {"hatch": np.concatenate(hatch) if hatch else empty,
            "rings": np.concatenate(rings) if rings else empty}


def _lines_anew(scene: viser.SceneApi, old: viser.LineSegmentsHandle | None, name: str,
                segments: npt.NDArray[np.float64], color: tuple[int, int, int],
                width: float) -> viser.LineSegmentsHandle | None:
    """``old`` removed and ``segments`` drawn as ``/grasp/obstacles/<name>`` (None: none)."""
    if old is not None:
        old.remove()
    if not len(segments):
        return None
    return scene.add_line_segments(f"/grasp/obstacles/{name}", segments, color, thickness=width)


class ObstacleLayer:
    """Scene nodes of the obstacles (one body per obstacle; hatching and rings batched)."""

    def __init__(self, server) -> None:
        self.server = server
        # Line nodes, made by sync.
        self.hatch: viser.LineSegmentsHandle | None = None
        self.rings: viser.LineSegmentsHandle | None = None
        self.ring_sel: viser.LineSegmentsHandle | None = None
        self.bodies: dict[str, tuple[Any, Obstacle]] = {}
        self._made = 0

    def sync(self, obstacles: Sequence[Obstacle], selected: str | None,
             clearance: float) -> None:
        """Create, move or remove nodes to show ``obstacles``."""
        scene = self.server.scene
        wanted = {o.name: o for o in obstacles}
        for name in list(self.bodies):
            if name not in wanted or self.bodies[name][1] != wanted[name]:
                self.bodies.pop(name)[0].remove()
        for o in obstacles:
            if o.name not in self.bodies:
                self._made += 1
                v, f = object_mesh(o.r, OBSTACLE_HEIGHT)
                body = scene.add_mesh_simple(f"/grasp/obstacles/body_{self._made}", v, f,
                                             color=OBSTACLE_COLOR, position=(o.x, o.y, 0.0),
                                             cast_shadow=False)
                self.bodies[o.name] = (body, o)
        g = obstacle_geometry(obstacles, clearance)
        sel = wanted.get(selected) if selected is not None else None
        ring_sel = (circle_segments((sel.x, sel.y), [sel.r + clearance], RING_Z + 0.0005)
                    if sel is not None else np.zeros((0, 2, 3)))
        # Line nodes are made anew with their colours (a points update before its colours
        # reach the browser drew the lines white, and these change rarely).
        self.hatch = _lines_anew(scene, self.hatch, "hatch", g["hatch"], HATCH_COLOR, 0.0025)
        self.rings = _lines_anew(scene, self.rings, "rings", g["rings"], RING_COLOR, 0.003)
        self.ring_sel = _lines_anew(scene, self.ring_sel, "ring_sel", ring_sel, RING_COLOR,
                                    0.007)


def recorded_disk(entry: Any) -> tuple[float, float, float] | None:
    """``(x, y, r)`` of a recorded disk (an object, obstacle or bin: m), or None when the entry
    is malformed, not finite or its radius is outside (0, 1] m (replays skip such entries)."""
    try:
        x, y, r = float(entry["x"]), float(entry["y"]), float(entry["r"])
    except (KeyError, TypeError, ValueError):
        return None
    if not (np.isfinite([x, y, r]).all() and 0.0 < r <= 1.0):
        return None
    return x, y, r


def draw_recorded_obstacles(scene, data: dict[str, Any] | None, root: str) -> list[Any]:
    """Draw the obstacles of a recorded ``objects`` record (replay, export) under ``root``;
    bad entries are skipped. Returns the nodes (the caller removes them when they change)."""
    nodes: list[Any] = []
    if not data:
        return nodes
    try:
        clearance = max(float(data.get("clearance") or 0.0), 0.0)
    except (TypeError, ValueError):
        clearance = 0.0
    for i, o in enumerate(data.get("obstacles") or []):
        disk = recorded_disk(o)
        if disk is None:
            continue
        x, y, r = disk
        v, f = object_mesh(r, OBSTACLE_HEIGHT)
        nodes.append(scene.add_mesh_simple(f"{root}/body_{i}", v, f, color=OBSTACLE_COLOR,
                                           position=(x, y, 0.0), cast_shadow=False))
        segs = np.concatenate([hatch_segments(x, y, r, OBSTACLE_HEIGHT + 0.001),
                               circle_segments((x, y), [r + clearance], RING_Z)])
        nodes.append(scene.add_line_segments(f"{root}/lines_{i}", segs, HATCH_COLOR,
                                             thickness=0.003))
    return nodes
