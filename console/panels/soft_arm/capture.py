"""Capture-region panel (soft arm): simulate Fig. 6 with a progress bar and draw the map.

*Characterise* runs :func:`core.control.capture.characterise` (grasps on a grid relative to the
gripper, the simulated closing sweep) in a spawned worker process, a few grid rows per job so
the progress bar moves; the merged map is drawn as SVG (blue dots: captured, red crosses:
missed, grey circle: the paper's model of half a gripper length) and can be saved to the
console's data folder. With a two-finger gripper (``[gripper] fingers = "both"``) *Side* picks
the left finger (the paper's), the right one, or both: then both maps are drawn, each with its
summary, and a line says in how many cells the right map is the left one's mirror image.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import threading

import numpy as np
import viser

from console.panels.common.base import Panel, operator_only
from console.panels.common.events import client_of
from core.control.capture import CaptureMap, characterise, grid_rows, mirror_agreement
from core.robots import load
from core.units import MM_PER_M, fmt_mm
from hw_bridge.parent_watch import pool_initializer

CHUNKS = 8


SIDE_LABELS = {"Left finger": ("left",), "Right finger": ("right",), "Both": ("left", "right")}


def _chunk(robot_src: str, radius: float, spacing: float, repeats: int,
           y_range: tuple[float, float], seed: int, side: str = "left") -> CaptureMap:
    robot = load(robot_src)
    return characterise(robot, radius, side=side, spacing=spacing, y_range=y_range,
                        repeats=repeats, seed=seed)


def merge(parts: list[CaptureMap]) -> CaptureMap:
    """Stack row chunks (same x grid, consecutive y ranges) into one map."""
    parts = sorted(parts, key=lambda m: m.ys[0])
    first = parts[0]
    return CaptureMap(first.xs, np.concatenate([p.ys for p in parts]), first.radius, first.spacing,
                      first.repeats, np.concatenate([p.outcome for p in parts]),
                      np.concatenate([p.rate for p in parts]), first.model, first.gripper_open,
                      first.gripper_closed, first.side)


def summary_markdown(m: CaptureMap, named: bool = False) -> str:
    """The map's result in words, lengths in mm (the map's grid is whole millimetres);
    ``named``: headed by the finger's side."""
    cx, cy = m.centroid()
    finger = f"**{m.side} finger:** " if named else ""
    return (f"{finger}{m.successes} captures of an r = {fmt_mm(m.radius)} mm object on a "
            f"{fmt_mm(m.spacing, 0)} mm grid · equivalent diameter "
            f"**{fmt_mm(m.equivalent_diameter(), 0)} mm** (paper: about half a gripper length, "
            f"{fmt_mm(m.model.diameter, 0)} mm) · centroid ({fmt_mm(cx, 0)}, {fmt_mm(cy, 0)}) mm "
            f"in the gripper frame · agreement with the model {m.model_agreement():.0%}")


class CapturePanel(Panel):
    """Capture-region characterisation with progress and the Fig. 6 drawing."""

    title = "Capture region"
    tab = "Experiments"
    order = 55.0
    kinds = ("planar",)

    def build(self) -> None:
        gui = self.gui
        robot = self.app.robot
        self.radius = gui.add_number(
            "Object r (mm)", round(robot.capture.nominal_object_radius * MM_PER_M, 3), min=5.0,
            max=round(robot.gripper.max_object_radius * MM_PER_M, 3), step=0.5)
        self.spacing = gui.add_number("Grid (mm)", 5.0, min=2.0, max=20.0, step=1.0)
        self.repeats = gui.add_slider("Repeats (±1 mm)", min=1, max=5, step=1, initial_value=1)
        two = "right" in robot.gripper.sides
        self.side = gui.add_dropdown("Side", tuple(SIDE_LABELS) if two else ("Left finger",),
                                     initial_value="Both" if two else "Left finger",
                                     disabled=not two)
        self.run_btn = gui.add_button("Characterise", icon=viser.Icon.PLAYER_PLAY)
        self.save_btn = gui.add_button("Save map (JSON)", icon=viser.Icon.DEVICE_FLOPPY,
                                       disabled=True)
        self.progress = gui.add_progress_bar(0.0, visible=False)
        self.summary = gui.add_markdown("<small>no map yet</small>")
        self.drawing = gui.add_html("")
        self.run_btn.on_click(operator_only(lambda e: self._start(), panel=self,
                                            action="run the characterisation"))
        self.save_btn.on_click(operator_only(lambda e: self._save(e), panel=self,
                                             action="save the map"))
        self.maps: dict[str, CaptureMap] = {}
        self._thread: threading.Thread | None = None

    @property
    def map(self) -> CaptureMap | None:
        """The newest map (the left finger's when both were characterised)."""
        return next(iter(self.maps.values()), None)

    def _start(self) -> None:
        if self._thread is not None and self._thread.is_alive():
            return
        self.run_btn.disabled = True
        self.progress.value, self.progress.visible = 0.0, True
        self._thread = threading.Thread(target=self._run, name="capture-map", daemon=True,
                                        args=(float(self.radius.value) / MM_PER_M,
                                              float(self.spacing.value) / MM_PER_M,
                                              int(self.repeats.value),
                                              SIDE_LABELS[str(self.side.value)]))
        self._thread.start()

    def _run(self, radius: float, spacing: float, repeats: int,
             sides: tuple[str, ...] = ("left",)) -> None:
        robot = self.app.robot
        jobs = []
        for side in sides:
            ys = grid_rows(robot, spacing, side)
            jobs += [(side, (float(c[0]), float(c[-1])))
                     for c in np.array_split(ys, min(CHUNKS, len(ys)))]
        try:
            ctx = multiprocessing.get_context("spawn")
            with cf.ProcessPoolExecutor(1, mp_context=ctx, initializer=pool_initializer) as pool:
                futs = {pool.submit(_chunk, str(robot.source), radius, spacing, repeats, b, i,
                                    side): side for i, (side, b) in enumerate(jobs)}
                parts: dict[str, list[CaptureMap]] = {side: [] for side in sides}
                for k, f in enumerate(cf.as_completed(futs), 1):
                    parts[futs[f]].append(f.result())
                    self.progress.value = 100.0 * k / len(futs)
            self.maps = {side: merge(parts[side]) for side in sides}
            self.summary.content = "\n\n".join(summary_markdown(m, len(self.maps) > 1)
                                                 for m in self.maps.values())
            if len(self.maps) == 2:
                agree = mirror_agreement(self.maps["left"], self.maps["right"])
                self.summary.content += (f"\n\nRight map = the left one mirrored in "
                                         f"**{agree:.0%}** of the cells")
            fitted = lambda m: m.to_svg(scale=2500.0).replace(  # noqa: E731 - the panel's width
                "<svg ", "<svg style='max-width:100%;height:auto' ", 1)
            self.drawing.content = "".join(
                f"<div><small>{side} finger</small>{fitted(m)}</div>" if len(self.maps) > 1
                else fitted(m) for side, m in self.maps.items())
            self.save_btn.disabled = False
        except Exception as exc:  # report, never kill the console
            self.summary.content = f"**Characterisation failed:** {exc}"
        finally:
            self.run_btn.disabled = False
            self.progress.visible = False

    def _save(self, event: object) -> None:
        if not self.maps:
            return
        data = self.app.data
        paths = []
        for side, cmap in self.maps.items():
            stem = "capture_map" if side == "left" else f"capture_map_{side}"
            path = data.path("exports", data.new_name("exports", stem, ".json"), ".json")
            cmap.save(path)
            paths.append(str(path))
        client = client_of(event)
        if client is not None:
            client.add_notification("Saved", ", ".join(paths), auto_close_seconds=6.0)
