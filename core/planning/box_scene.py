"""The extensible arm's obstacle scene: box obstacles and their clearance, checked and as JSON.

A :class:`BoxScene` is what the operator placed (shelves, drawer walls: axis-aligned boxes in
the arm's base frame) and the clearance the arm's body surface keeps from them. Scene files are
JSON in metres::

    {"format": "extensible-boxes/1", "clearance": 0.02,
     "boxes": [{"name": "Shelf", "centre": [0.2, 0.0, 0.25], "size": [0.2, 0.3, 0.02]}]}

:func:`scene_from_json` refuses a bad file with its reason (not JSON, a missing field, NaN, a
size <= 0, duplicate names, a box that contains the arm's base or leaves the body there less
than the clearance); :meth:`BoxScene.with_box` and friends refuse bad edits the same way, so a
refused edit changes nothing. The body radius the base check counts is the robot file's
``[segments] body_radius``, given to the scene (``body_radius``); it is not part of the file
(the same scene suits any arm) nor of a scene's equality.
"""

from __future__ import annotations

import dataclasses
import json
from typing import Any

from core.kinematics import box_clearance as bc

FORMAT = "extensible-boxes/1"
DEFAULT_CLEARANCE = 0.02  # m, the scene's default (an operator setting, not a robot parameter)


@dataclasses.dataclass(frozen=True)
class BoxScene:
    """Boxes (unique names) and the clearance (m) the arm's body surface keeps from each.

    ``body_radius`` (m) is the robot's (``ExtensibleArm.body_radius``), used only to check that
    no box comes within the clearance of the body at the base; 0 checks the base point alone.
    Edits keep it; it takes no part in equality (the scene is the boxes and the clearance).
    """

    boxes: tuple[bc.Box, ...] = ()
    clearance: float = DEFAULT_CLEARANCE
    body_radius: float = dataclasses.field(default=0.0, compare=False)

    def __post_init__(self) -> None:
        bc.check_clearance(self.clearance)
        names = [b.name for b in self.boxes]
        if len(set(names)) != len(names):
            dup = next(n for n in names if names.count(n) > 1)
            raise ValueError(f"box names must be unique ('{dup}' twice)")
        for box in self.boxes:
            if not isinstance(box, bc.Box):
                raise ValueError("boxes must be Box objects")
            bc.check_box_for_base(box, self.clearance, self.body_radius)

    def names(self) -> list[str]:
        return [b.name for b in self.boxes]

    def get(self, name: str) -> bc.Box:
        for b in self.boxes:
            if b.name == name:
                return b
        raise ValueError(f"no box named '{name}'")

    def with_box(self, box: bc.Box) -> BoxScene:
        """This scene plus ``box`` (ValueError for a name in use or a box at the base)."""
        if box.name in self.names():
            raise ValueError(f"a box named '{box.name}' exists already")
        return dataclasses.replace(self, boxes=self.boxes + (box,))

    def replaced(self, name: str, box: bc.Box) -> BoxScene:
        """Box ``name`` replaced by ``box`` (which may be renamed)."""
        self.get(name)
        if box.name != name and box.name in self.names():
            raise ValueError(f"a box named '{box.name}' exists already")
        return dataclasses.replace(
            self, boxes=tuple(box if b.name == name else b for b in self.boxes))

    def without(self, name: str) -> BoxScene:
        self.get(name)
        return dataclasses.replace(self, boxes=tuple(b for b in self.boxes if b.name != name))

    def with_clearance(self, clearance: float) -> BoxScene:
        return dataclasses.replace(self, clearance=bc.check_clearance(clearance))

    def free_name(self, stem: str = "Box") -> str:
        """The first of "Box 1", "Box 2", ... not in use."""
        k = 1
        while f"{stem} {k}" in self.names():
            k += 1
        return f"{stem} {k}"


def scene_to_dict(scene: BoxScene) -> dict[str, Any]:
    """The scene as JSON-able data (metres)."""
    return {"format": FORMAT, "clearance": scene.clearance,
            "boxes": [{"name": b.name, "centre": list(b.centre), "size": list(b.size)}
                      for b in scene.boxes]}


def scene_to_json(scene: BoxScene) -> str:
    """Scene JSON (see the module docstring)."""
    return json.dumps(scene_to_dict(scene), indent=1)


def scene_from_dict(data: Any, body_radius: float = 0.0) -> BoxScene:
    """A checked scene from :func:`scene_to_dict`'s data (base check with the arm's
    ``body_radius``, m); ValueError with the reason."""
    if not isinstance(data, dict) or not isinstance(data.get("boxes"), list):
        raise ValueError("not a box scene: expected an object with a 'boxes' list")
    if data.get("format", FORMAT) != FORMAT:
        raise ValueError(f"not a box scene: format {data.get('format')!r}, expected {FORMAT!r}")
    boxes: list[bc.Box] = []
    for i, item in enumerate(data["boxes"]):
        if not isinstance(item, dict):
            raise ValueError(f"box {i + 1}: expected an object with name, centre and size")
        missing = [k for k in ("centre", "size") if k not in item]
        if missing:
            raise ValueError(f"box {i + 1}: missing {', '.join(missing)}")
        boxes.append(bc.make_box(str(item.get("name", f"Box {i + 1}")), item["centre"],
                                 item["size"]))
    return BoxScene(tuple(boxes), bc.check_clearance(data.get("clearance", DEFAULT_CLEARANCE)),
                    body_radius)


def scene_from_json(text: str | bytes, body_radius: float = 0.0) -> BoxScene:
    """Parse and check scene JSON (base check with the arm's ``body_radius``, m); ValueError
    (with the reason) for a bad file."""
    try:
        data = json.loads(text)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"not JSON ({exc})") from None
    return scene_from_dict(data, body_radius)

