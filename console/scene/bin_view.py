"""The bin in the 3D scene, so every browser sees where "Clear table into bin" takes the objects:
an open box (:data:`console.core.table_bin.BIN_COLOR`) with a "Bin" label; with no bin
placed, where the robot file's ``[bin]`` drops the objects instead (Execute and the row go there
then): the same box dimmed (:data:`ROBOT_FILE_OPACITY`) at each finger's drop point, one label
"robot file's bin" over them.

The grasp session keeps the bin (:class:`console.core.table_bin.TableBin`); the grasp layers
(:class:`console.scene.grasp_layers.GraspSceneView`) draw it here when it changed.
"""

from __future__ import annotations

from typing import Any

from console.core.table_bin import (BIN_COLOR, BIN_HEIGHT, TableBin, open_box_mesh,
                                    robot_file_drops)

ROBOT_FILE_OPACITY = 0.35  # the robot file's bin, drawn while no bin is placed
ROBOT_FILE_LABEL = "robot file's bin"


class BinView:
    """The bin in the 3D scene: an open box (``BIN_COLOR``) with a "Bin" label; with no bin
    placed and ``robot`` given, the robot file's bin dimmed (see the module docstring)."""

    def __init__(self, scene: Any, robot: Any = None) -> None:
        self.scene = scene
        self.shown: TableBin | None = None
        self.box: Any = None
        self._half = 0.0
        self.label = scene.add_label("/row/bin/label", "Bin", position=(0.0, 0.0, 0.0),
                                     visible=False, anchor="bottom-center")
        self.defaults: list[Any] = []  # the robot file's bin: its boxes, then its label
        if robot is not None:
            drops = robot_file_drops(robot)
            v, f = open_box_mesh(float(robot.bin.drop_radius_m))
            for side, x, y in drops:
                self.defaults.append(scene.add_mesh_simple(
                    f"/row/robot_file_bin/{side}/box", v, f, color=BIN_COLOR, side="double",
                    opacity=ROBOT_FILE_OPACITY, cast_shadow=False, position=(x, y, 0.0)))
            # One label over the boxes (one per finger, 73 mm apart on the shipped arm: a
            # label per box, "(left finger)" and "(right finger)", overlapped on screen).
            mx = sum(x for _, x, _ in drops) / len(drops)
            my = sum(y for _, _, y in drops) / len(drops)
            self.defaults.append(scene.add_label(
                "/row/robot_file_bin/label", ROBOT_FILE_LABEL,
                position=(mx, my, BIN_HEIGHT + 0.01), anchor="bottom-center"))

    def draw(self, table_bin: TableBin | None) -> None:
        """Show ``table_bin`` (None hides the bin); does nothing when it did not change."""
        if table_bin == self.shown:
            return
        self.shown = table_bin
        for node in self.defaults:  # the robot file's bin stands in while none is placed
            node.visible = table_bin is None
        if table_bin is None:
            if self.box is not None:
                self.box.visible = False
            self.label.visible = False
            return
        if self.box is None or self._half != table_bin.drop_radius:
            if self.box is not None:
                self.box.remove()
            self._half = table_bin.drop_radius
            v, f = open_box_mesh(table_bin.drop_radius)
            self.box = self.scene.add_mesh_simple("/row/bin/box", v, f, color=BIN_COLOR,
                                                  side="double", cast_shadow=False)
        self.box.position = (table_bin.x, table_bin.y, 0.0)
        self.box.visible = True
        self.label.position = (table_bin.x, table_bin.y, BIN_HEIGHT + 0.01)
        self.label.visible = True
