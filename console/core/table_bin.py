"""The bin the operator places on the table, where "Clear table into bin" takes every object.

A click on the table (Objects panel, "Table click places: Bin") gives a point; the arm must be
able to hold an object over it, so :func:`locate_bin` turns the point into the configuration
``move_to_bin`` goes to (:func:`core.control.row.bin_at`, a grasp plan's final pose: up to a
second of work, so :class:`BinLocator` runs it on a thread of its own and keeps only the newest
click's answer). The grasp session keeps the :class:`TableBin` (shared by every browser, saved
in the scene JSON under an optional ``"bin"`` key and in recordings with the objects);
:class:`console.scene.bin_view.BinView` draws it: an open box on the table in its own colour,
labelled "Bin" (:func:`open_box_mesh`).
"""

from __future__ import annotations

import dataclasses
import json
import threading
from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt

from core.control.params import BinParams
from core.control.row import bin_at

Array = npt.NDArray[np.float64]
BIN_COLOR = (20, 125, 125)   # teal: unlike the objects (purple / pink) and the table
BIN_HEIGHT = 0.04            # m, the open box's walls
BIN_WALL = 0.004             # m


@dataclasses.dataclass(frozen=True)
class TableBin:
    """A bin at ``(x, y)`` on the table (m); ``kappa`` (1/m) holds an object over it,
    ``kappa_right`` one the right finger holds (empty for a gripper with the left finger only)."""

    x: float
    y: float
    kappa: tuple[float, ...]
    drop_radius: float  # m: the robot file's [bin] drop radius (the box's half width)
    kappa_right: tuple[float, ...] = ()

    def describe(self) -> str:
        return f"bin at ({self.x * 1e3:.0f}, {self.y * 1e3:.0f}) mm"

    def params(self) -> BinParams:
        """As the state machine's ``BinParams`` (what :func:`locate_bin` was made from)."""
        right = np.asarray(self.kappa_right, float) if self.kappa_right else None
        return BinParams(np.asarray(self.kappa, float), self.drop_radius, right)

    def record(self) -> dict[str, float]:
        """For the scene JSON and recordings: where it is (the pose is found again on load)."""
        return {"x": float(self.x), "y": float(self.y), "r": float(self.drop_radius)}


def robot_file_drops(robot: Any, radius: float | None = None) -> list[tuple[str, float, float]]:
    """Where the robot file's ``[bin]`` drops an object of ``radius`` (m; default the robot's
    nominal object) when no bin is placed: ``(finger side, x, y)`` per finger of the gripper,
    the held object's centre with the arm in the ``[bin]`` pose (m)."""
    from core.control.params import BinParams
    from core.control.row import bin_drop_point
    r = robot.capture.nominal_object_radius if radius is None else float(radius)
    params = BinParams.from_robot(robot)
    drops = []
    for side in tuple(robot.gripper.sides):
        x, y = bin_drop_point(robot, params.kappa_for(side), r, side)
        drops.append((side, float(x), float(y)))
    return drops


def locate_bin(robot: Any, x: float, y: float) -> TableBin:
    """The bin at ``(x, y)``; ValueError with the reason when the arm cannot hold an object
    over it (out of reach, on the arm, not a finite point)."""
    params = bin_at(robot, float(x), float(y))
    right = () if params.kappa_right is None else tuple(float(k) for k in params.kappa_right)
    return TableBin(float(x), float(y), tuple(float(k) for k in params.kappa),
                    float(params.drop_radius_m), right)


def box_distance(px: Any, py: Any, x: float, y: float, half: float) -> Any:
    """Distance (m) from points ``(px, py)`` (scalars or arrays) to the bin's square box of half
    width ``half`` centred at ``(x, y)``; 0 inside it."""
    return np.hypot(np.maximum(np.abs(px - x) - half, 0.0), np.maximum(np.abs(py - y) - half, 0.0))


def bin_overlap(x: float, y: float, half: float, obstacles: Any) -> str | None:
    """Why the bin's box (half width ``half``, m) cannot stand at ``(x, y)``: it would overlap
    one of ``obstacles`` (disks with ``name``, ``x``, ``y``, ``r``); None when it is clear."""
    for o in obstacles:
        outside = float(box_distance(o.x, o.y, x, y, half))
        if outside < o.r:
            return (f"the bin's box ({2 * half * 1e3:.0f} mm wide) at ({x * 1e3:.0f}, "
                    f"{y * 1e3:.0f}) mm would stand on {o.name} (by {(o.r - outside) * 1e3:.0f} "
                    f"mm): click farther from it, or move {o.name}")
    return None


def bin_on_arm(robot: Any, x: float, y: float, half: float) -> str | None:
    """Why the bin's box (half width ``half``, m) cannot stand at ``(x, y)``: it would cover
    the arm in its straight start pose (the body from the base to the tip, ``half_width`` to each
    side, and the gripper beyond the tip, as capsules like the planner's clearances;
    :func:`locate_bin` checks only that an object can be held over the point); None when it
    is clear."""
    from core.planning.arm_model import ArmModel
    model = ArmModel.from_robot(robot)
    tip, heading = model.point_py([0.0] * model.n)
    end = tip + robot.gripper.length * complex(np.cos(heading), np.sin(heading))
    t = np.linspace(0.0, 1.0, 401)[:, None]
    pts = np.concatenate([model.base + (tip - model.base) * t, tip + (end - tip) * t])[:, 0]
    width = np.concatenate([np.full(401, float(robot.half_width)),
                            np.full(401, float(robot.gripper.half_width))])
    outside = box_distance(pts.real, pts.imag, x, y, half)
    depth = float(np.max(width - outside))
    if depth <= 1e-9:  # (touching is clear)
        return None
    return (f"the bin's box ({2 * half * 1e3:.0f} mm wide) at ({x * 1e3:.0f}, {y * 1e3:.0f}) mm "
            f"would cover the arm where it starts, straight (by {depth * 1e3:.0f} mm): click "
            "farther from the arm")


def scene_json_with_bin(scene_text: str, table_bin: TableBin | None) -> str:
    """Scene JSON (``console.core.table_scene.scene_to_json``) with the bin under ``"bin"`` if any."""
    data = json.loads(scene_text)
    if table_bin is not None:
        data["bin"] = table_bin.record()
    return json.dumps(data, indent=1)


def bin_point_from_scene_json(text: str) -> tuple[float, float] | None:
    """The bin's point from scene JSON (None when the file has no ``"bin"``: older files);
    ValueError for a bin entry that is not a finite point."""
    try:
        entry = json.loads(text).get("bin")
        if entry is None:
            return None
        x, y = float(entry["x"]), float(entry["y"])
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        raise ValueError(f"the scene's bin is not a point ({type(exc).__name__}: {exc})") from None
    if not (np.isfinite(x) and np.isfinite(y)):
        raise ValueError("the scene's bin is not a finite point")
    return x, y


class BinLocator:
    """Finds bins off the GUI threads: ``request(x, y, done)`` runs :func:`locate_bin` on a
    worker thread and calls ``done(TableBin | None, error | None)`` -- only for the newest
    request (a click superseded while it was worked out is dropped)."""

    def __init__(self, robot: Any) -> None:
        self.robot = robot
        self._lock = threading.Lock()
        self._seq = 0

    def request(self, x: float, y: float,
                done: Callable[[TableBin | None, str | None], None]) -> None:
        with self._lock:
            self._seq += 1
            seq = self._seq

        def work() -> None:
            try:
                found, error = locate_bin(self.robot, x, y), None
            except ValueError as exc:
                found, error = None, str(exc)
            with self._lock:
                if seq != self._seq:
                    return
            done(found, error)

        threading.Thread(target=work, name="bin-locator", daemon=True).start()


def open_box_mesh(half: float, height: float = BIN_HEIGHT,
                  wall: float = BIN_WALL) -> tuple[Array, Any]:
    """Four walls of a square box, open at the top, centred on the origin (no floor)."""
    side = half - wall / 2  # the walls' centre lines
    walls = ((0, side, half, wall / 2), (0, -side, half, wall / 2),
             (side, 0, wall / 2, half), (-side, 0, wall / 2, half))
    boxes = [_cuboid(cx, cy, hx, hy, height) for cx, cy, hx, hy in walls]
    verts = np.concatenate([v for v, _ in boxes])
    faces = np.concatenate([f + 8 * i for i, (_, f) in enumerate(boxes)])
    return verts, faces.astype(np.uint32)


def _cuboid(cx: float, cy: float, hx: float, hy: float, h: float) -> tuple[Array, Any]:
    v = np.array([[cx + sx * hx, cy + sy * hy, z] for z in (0.0, h)
                  for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))], float)
    f = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
                  [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]])
    return v, f
