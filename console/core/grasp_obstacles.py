"""The grasp session's obstacle edits: place, select, change, remove obstacles, load a scene
with them and set the clearance plans keep from them.

A mixin of :class:`console.core.grasp_session.GraspSession` (same lock and worker rules: every
method takes the session's lock, validates first -- a bad obstacle raises ValueError and changes
nothing -- then marks ``obstacles`` dirty and asks for a plan).
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Callable

import numpy as np

from console.core.table_scene import TableObject, disk_overlap, validate_obstacles
from core.planning.obstacles import Obstacle, check_clearance

DEFAULT_CLEARANCE = 0.010   # m between the arm (gripper included) and any obstacle
DEFAULT_OBSTACLE_RADIUS = 0.02


class ObstacleEdits:
    """Obstacle state and edits of a grasp session (see the module docstring)."""

    robot: object
    clearance: float
    _cond: threading.Condition
    _obstacles: list[Obstacle]
    _obstacle_selected: str | None
    _obstacle_count: int
    _objects: list[TableObject]
    _selected: str | None
    _changed: Callable[..., None]

    def place_obstacle(self, x: float, y: float, r: float | None = None) -> str:
        """Select the obstacle under (x, y), or add a new one there (ValueError for a bad one,
        or one that would overlap an object: nothing changes then); returns its name."""
        with self._cond:
            for o in self._obstacles:
                if np.hypot(o.x - x, o.y - y) <= o.r + 0.005:
                    self._obstacle_selected = o.name
                    self._changed("obstacles")
                    return o.name
            names = {o.name for o in self._obstacles}
            k = self._obstacle_count + 1
            while f"Obstacle {k}" in names:
                k += 1
            new = Obstacle(f"Obstacle {k}", float(x), float(y),
                           float(DEFAULT_OBSTACLE_RADIUS if r is None else r))
            validate_obstacles(self._obstacles + [new], self.robot)
            why = disk_overlap(new.name, new.x, new.y, new.r, self._objects)
            if why is not None:  # an object would be hidden inside it
                raise ValueError(why)
            self._obstacle_count = k
            self._obstacles.append(new)
            self._obstacle_selected = new.name
            self._changed("obstacles", plan=False)
            return new.name

    def update_obstacle(self, name: str, *, x: float | None = None, y: float | None = None,
                        r: float | None = None) -> None:
        """Change an obstacle (ValueError for bad values or an overlap with an object: nothing
        changes then)."""
        with self._cond:
            i = self._find_obstacle(name)
            old = self._obstacles[i]
            new = dataclasses.replace(old, x=old.x if x is None else float(x),
                                      y=old.y if y is None else float(y),
                                      r=old.r if r is None else float(r))
            obstacles = list(self._obstacles)
            obstacles[i] = new
            validate_obstacles(obstacles, self.robot)
            why = disk_overlap(name, new.x, new.y, new.r, self._objects)
            if why is not None:
                raise ValueError(why.replace("Not placed", "Not changed", 1))
            self._obstacles = obstacles
            self._changed("obstacles", plan=False)

    def remove_obstacle(self, name: str) -> None:
        with self._cond:
            self._obstacles.pop(self._find_obstacle(name))
            if self._obstacle_selected == name:
                self._obstacle_selected = self._obstacles[-1].name if self._obstacles else None
            self._changed("obstacles", plan=False)

    def select_obstacle(self, name: str | None) -> None:
        with self._cond:
            if name is not None:
                self._find_obstacle(name)
            self._obstacle_selected = name
            self._changed("obstacles")

    def set_scene(self, objects: list[TableObject], obstacles: list[Obstacle]) -> None:
        """Replace the objects and the obstacles (a loaded scene file; already validated)."""
        with self._cond:
            self._objects = list(objects)
            self._selected = objects[0].name if objects else None
            self._obstacles = list(obstacles)
            self._obstacle_selected = obstacles[0].name if obstacles else None
            self._changed("objects", "obstacles", plan=False)

    def set_clearance(self, clearance: float) -> None:
        """The clearance (m) plans keep from every obstacle (ValueError if not 0..200 mm)."""
        value = check_clearance(clearance)
        with self._cond:
            self.clearance = value
            self._changed("obstacles", plan=False)

    def _find_obstacle(self, name: str) -> int:
        for i, o in enumerate(self._obstacles):
            if o.name == name:
                return i
        raise ValueError(f"no obstacle named {name!r}")
