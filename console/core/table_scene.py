"""The objects and obstacles on the table as checked data, and the scene files that hold them.

:class:`TableObject` is an object to grasp (the paper's enclosing cylinder); obstacles are
:class:`core.planning.obstacles.Obstacle`. Scene JSON is
``{"objects": [{"name", "x", "y", "r"}, ...], "obstacles": [{"name", "x", "y", "r"}, ...]}`` in
metres (``obstacles`` is optional: older files without it load with none). A bad object, obstacle
or file raises ValueError with the operator's message and changes nothing. Drawn by
:mod:`console.scene.plan_view` (objects) and :mod:`console.scene.obstacle_view` (obstacles).
"""

from __future__ import annotations

import dataclasses
import json
import math

from core.planning.arm_model import ArmModel
from core.planning.obstacles import Obstacle, check_obstacles, first_overlap


@dataclasses.dataclass(frozen=True)
class TableObject:
    """A cylinder on the table (the paper's enclosing cylinder of the object)."""

    name: str
    x: float
    y: float
    r: float


def validate_object(obj: TableObject, robot) -> TableObject:
    """Raise ValueError with an operator message if ``obj`` is not a sensible object."""
    if not all(math.isfinite(v) for v in (obj.x, obj.y, obj.r)):
        raise ValueError("object position and radius must be finite numbers")
    if not 0.002 <= obj.r <= 0.2:
        raise ValueError(f"object radius must be between 2 and 200 mm, got {obj.r * 1e3:.1f} mm")
    if max(abs(obj.x), abs(obj.y)) > 2.0:
        raise ValueError("object must lie on the table (within 2 m of the base)")
    return obj


def disk_overlap(what: str, x: float, y: float, r: float, others) -> str | None:
    """Why the disk ``what`` (centre ``(x, y)``, radius ``r``, m) may not be placed: it would
    overlap one of ``others`` (disks with ``name``, ``x``, ``y``, ``r``: objects or obstacles),
    as the planner would refuse it later; None when it is clear of them all."""
    hit = first_overlap(x, y, r, others)  # the planner's own test (it refuses the same)
    if hit is None:
        return None
    o, gap = hit
    return (f"Not placed: {what} (r {r * 1e3:.1f} mm) at ({x * 1e3:.0f}, {y * 1e3:.0f}) "
            f"mm would overlap {o.name} (by {-gap * 1e3:.0f} mm): place it farther "
            f"from {o.name}, or move {o.name}")


def validate_obstacles(obstacles: list[Obstacle], robot) -> list[Obstacle]:
    """Raise ValueError with an operator message for a bad obstacle (not finite, radius not
    positive, on the arm's base, names not unique); else return them."""
    return list(check_obstacles(obstacles, ArmModel.from_robot(robot),
                                robot.planner.base_keepout))


@dataclasses.dataclass(frozen=True)
class Scene:
    """What a scene file holds: the table objects and the obstacles."""

    objects: list[TableObject]
    obstacles: list[Obstacle]


def scene_to_json(objects: list[TableObject], obstacles: list[Obstacle] = ()) -> str:
    """Scene JSON (objects and obstacles in metres)."""
    return json.dumps({"objects": [dataclasses.asdict(o) for o in objects],
                       "obstacles": [dataclasses.asdict(o) for o in obstacles]}, indent=1)


def _items(data, key: str, kind: type, label: str) -> list:
    return [kind(str(o.get("name", f"{label} {i + 1}")), float(o["x"]), float(o["y"]),
                 float(o["r"])) for i, o in enumerate(data[key])]


def parse_scene(text: str, robot) -> Scene:
    """Parse and validate scene JSON (objects and, if present, obstacles); ValueError (with
    the reason) changes nothing."""
    try:
        data = json.loads(text)
        objs = _items(data, "objects", TableObject, "Object")
        obstacles = (_items(data, "obstacles", Obstacle, "Obstacle")
                     if data.get("obstacles") is not None else [])
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        raise ValueError(f"not a scene file ({type(exc).__name__}: {exc})") from None
    names = [o.name for o in objs]
    if len(set(names)) != len(names):
        raise ValueError("object names must be unique")
    return Scene([validate_object(o, robot) for o in objs], validate_obstacles(obstacles, robot))


def scene_from_json(text: str, robot) -> list[TableObject]:
    """The objects of scene JSON (:func:`parse_scene`); ValueError changes nothing."""
    return parse_scene(text, robot).objects
