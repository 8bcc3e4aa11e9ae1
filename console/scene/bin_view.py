"""The bin in the 3D scene, so every browser sees where "Clear table into bin" takes the objects:
an open box (:data:`console.core.table_bin.BIN_COLOR`) with a "Bin" label, or nothing.

The grasp session keeps the bin (:class:`console.core.table_bin.TableBin`); the grasp layers
(:class:`console.scene.grasp_layers.GraspSceneView`) draw it here when it changed.
"""

from __future__ import annotations

from typing import Any

from console.core.table_bin import BIN_COLOR, BIN_HEIGHT, TableBin, open_box_mesh


class BinView:
    """The bin in the 3D scene: an open box (``BIN_COLOR``) with a "Bin" label, or nothing."""

    def __init__(self, scene: Any) -> None:
        self.scene = scene
        self.shown: TableBin | None = None
        self.box: Any = None
        self._half = 0.0
        self.label = scene.add_label("/row/bin/label", "Bin", position=(0.0, 0.0, 0.0),
                                     visible=False, anchor="bottom-center")

    def draw(self, table_bin: TableBin | None) -> None:
        """Show ``table_bin`` (None hides the bin); does nothing when it did not change."""
        if table_bin == self.shown:
            return
        self.shown = table_bin
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
