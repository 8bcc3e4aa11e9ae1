"""A design study's variant drawn beside the console's arm, so two designs are compared by eye.

:class:`StudyGhostView` follows :class:`console.core.design_study.DesignStudies`: when a variant
is shown it draws that robot file's arm at rest (straight; the extensible arm with its racks at
mid-range, where it starts: ``ArmModel.initial``), translucent and ghost-coloured, under one
node (:data:`ROOT`) offset along +x so neither arm hides the other, with a label naming the
variant and its segment count; when it is hidden the node goes. It is the arm's own drawing
(:func:`console.scene.arm_view_factory.make_arm_view`, ``"vertices"``: sent once, never
moved), so what is seen is the variant's geometry: its segments, lengths and gripper.
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
import numpy.typing as npt
import viser

from console.core.design_study import DesignStudies, ShownVariant
from console.core.model import model_for
from console.scene.arm_view import ArmView
from console.scene.arm_view_factory import make_arm_view
from core.robots import Robot

ROOT = "/design_study_variant"
GHOST_COLOR = (150, 120, 205)   # lavender: not the replay's grey ghost, not a live part
GHOST_OPACITY = 0.5
GAP = 0.1                       # m between the two arms' outlines


def ghost_offset(current: Robot, variant: Robot) -> npt.NDArray[np.float64]:
    """Where the variant's arm stands relative to the console's: along +x by both arms' widths
    (their half-widths twice over) plus :data:`GAP`, so the two never overlap at rest."""
    return np.array([GAP + 2.0 * (current.half_width + variant.half_width), 0.0, 0.0])


def _handles(view: ArmView[Any]) -> list[Any]:
    """Every scene handle a view keeps (attributes, lists and dicts of them)."""
    out: list[Any] = []
    for value in vars(view).values():
        items = value.values() if isinstance(value, dict) else (
            value if isinstance(value, list) else [value])
        out += [h for h in items if isinstance(h, viser.SceneNodeHandle)]
    return out


class StudyGhostView:
    """The shown variant's arm in the shared 3D view (every browser sees it).

    Args:
        server: The console's viser server.
        studies: The console's design studies (what is shown).
        robot: The console's own arm (for the offset).
    """

    def __init__(self, server: viser.ViserServer, studies: DesignStudies, robot: Robot) -> None:
        self.server = server
        self.studies = studies
        self.robot = robot
        self._lock = threading.Lock()
        self._root: viser.FrameHandle | None = None
        self.view: ArmView[Any] | None = None
        self.label: viser.LabelHandle | None = None
        self.drawn: ShownVariant | None = None
        studies.add_listener(self.refresh)

    def refresh(self) -> None:
        """Draw what the studies show (a new variant replaces the old one; none: removed)."""
        with self._lock:
            shown = self.studies.shown
            if shown is self.drawn:
                return
            if self._root is not None:
                self._root.remove()  # the arm's nodes and the label are its children
                self._root, self.view, self.label = None, None, None
            self.drawn = shown
            if shown is not None:
                self._draw(shown)

    def _draw(self, shown: ShownVariant) -> None:
        scene = self.server.scene
        model = model_for(shown.robot)
        offset = ghost_offset(self.robot, shown.robot)
        with self.server.atomic():  # one change in the browser: never a flash of arm colours
            self._root = scene.add_frame(ROOT, show_axes=False, position=offset)
            view = make_arm_view(scene, model, root=f"{ROOT}/arm", method="vertices",
                                 dead_band=None)
            view.update(model.initial())
            for handle in _handles(view):
                if hasattr(handle, "color") and hasattr(handle, "opacity"):
                    handle.color = GHOST_COLOR
                    handle.opacity = GHOST_OPACITY
            n = shown.robot.n_segments
            self.label = scene.add_label(
                f"{ROOT}/label", f"{shown.name} · {n} segment{'s' if n != 1 else ''}",
                position=self._label_position(shown.robot), anchor="bottom-center")
            self.view = view

    @staticmethod
    def _label_position(robot: Robot) -> tuple[float, float, float]:
        """On the table in front of the arm's base (-y)."""
        if robot.kind == "planar":
            x, y, _ = robot.base_pose
            return (float(x), float(y) - 0.03, 0.0)
        return (0.0, -(robot.half_width + 0.03), 0.0)
