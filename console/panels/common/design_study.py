"""Design study panel (Experiments tab): a study's results, a plot, and any variant's arm in 3D.

``python -m core.study ... --out DIR`` (issue 30) sweeps robot-file variants; with ``DIR`` under
the console's data folder (``--data-dir``, e.g. ``runs/studies/segments``) this panel:

* **Study** lists the study folders found there (*Refresh list* looks again); picking one opens
  it. *Or folder* + *Open folder* opens a typed folder, relative to the data folder. A folder outside
  it, missing, or without ``results.parquet`` / ``results.csv`` is refused with the reason in a
  notification to whoever asked, and nothing changes (the open study stays open).
* The table: one row per variant (its varied keys, every metric in mm, mm², mm³ or degrees
  where the column's unit says so, :mod:`console.panels.common.study_table`), each metric's
  best value bold, the best variant per metric named below it (core.study's own rule).
* A **Metric** plotted **over** a varied key (uPlot; one line per combination of the other keys).
* **Show variant** draws the chosen variant's arm (its robot file) at rest beside the
  console's own, translucent (:mod:`console.scene.study_ghost`); **Hide variant** removes it.

Nothing here moves the arm, so viewers may use every widget (``allow_viewers``): like the View
panel's cameras, though the study and the drawn variant are the same for every browser. The
state (the open study, the variant shown) is the console's
(:class:`console.core.design_study.DesignStudies`, ``app.design_study``); the panel renders it
whenever it changes and keeps only its widgets.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import viser
from viser import uplot

from console.core.design_study import DesignStudies, StudyError, StudyResults
from console.panels.common.base import Panel
from console.panels.common.events import client_of
from console.panels.common.study_table import column_unit, default_metric, plot_data, table_markdown

NONE_FOUND = "(no study in the data folder)"
NO_STUDY = "(open a study)"
AXIS_SIZE = 90  # px for the y axis's numbers (mm³ run to nine digits) and its unit
LINE_COLORS = ("#1c7ed6", "#e8590c", "#2f9e44", "#ae3ec9", "#f08c00", "#0c8599", "#e03131",
               "#5c677d")


class DesignStudyPanel(Panel):
    """Open a design study, read its table and plot, draw a variant beside the arm."""

    title = "Design study"
    tab = "Experiments"
    order = 70.0

    @property
    def studies(self) -> DesignStudies:
        """The console's design studies (``app.design_study``)."""
        return self.app.design_study

    def build(self) -> None:
        gui = self.gui
        found = self.studies.studies()
        self.pick = gui.add_dropdown("Study", tuple(found) or (NONE_FOUND,),
                                     hint="study folders under the console's data folder "
                                          "(python -m core.study --out DATA/studies/NAME)")
        self.refresh_btn = gui.add_button("Refresh list", icon=viser.Icon.REFRESH)
        self.path = gui.add_text("Or folder", "", hint="relative to the console's data folder")
        self.open_btn = gui.add_button("Open folder", icon=viser.Icon.FOLDER_OPEN)
        self.status = gui.add_markdown(f"<small>{len(found)} studies in the data folder; none "
                                       "open</small>")
        self.table = gui.add_markdown("")
        self.metric = gui.add_dropdown("Metric", (NO_STUDY,), disabled=True)
        self.over = gui.add_dropdown("Over key", (NO_STUDY,), disabled=True)
        self.plot = gui.add_uplot(
            data=(np.zeros(1), np.zeros(1)), series=(uplot.Series(label="x"),
                                                     uplot.Series(label="y")),
            scales={"x": uplot.Scale(time=False)}, aspect=1.6, visible=False)
        self.variant = gui.add_dropdown("Variant", (NO_STUDY,), disabled=True)
        self.show_btn = gui.add_button("Show variant", icon=viser.Icon.EYE, disabled=True)
        self.hide_btn = gui.add_button("Hide variant", icon=viser.Icon.EYE_OFF, disabled=True)
        self.shown = gui.add_markdown("")
        self.allow_viewers(self.pick, self.refresh_btn, self.path, self.open_btn, self.metric,
                           self.over, self.variant, self.show_btn, self.hide_btn)
        self.pick.on_update(self._on_pick)
        self.refresh_btn.on_click(lambda e: self._refresh_list())
        self.open_btn.on_click(self._on_open)
        self.metric.on_update(self._on_plot_choice)
        self.over.on_update(self._on_plot_choice)
        self.show_btn.on_click(self._on_show)
        self.hide_btn.on_click(lambda e: self.studies.hide())
        self.studies.add_listener(self.render)

    # -- callbacks: read the widget, call the studies, tell the asker what was refused ---------

    def _on_pick(self, event: viser.GuiEvent) -> None:
        if client_of(event) is None or self.pick.value == NONE_FOUND:
            return  # a server-side change of the options, or nothing to open
        self._open(event, str(self.pick.value))

    def _on_open(self, event: viser.GuiEvent) -> None:
        typed = str(self.path.value).strip()
        if not typed and self.pick.value == NONE_FOUND:
            self._tell(event, "Cannot open the study", "type a study folder (relative to the "
                       f"console's data folder, {self.studies.root})")
            return
        self._open(event, typed or str(self.pick.value))

    def _open(self, event: Any, folder: str) -> None:
        try:
            self.studies.open(folder)
        except StudyError as exc:
            self._tell(event, "Cannot open the study", str(exc))

    def _on_show(self, event: viser.GuiEvent) -> None:
        try:
            self.studies.show(str(self.variant.value))
        except StudyError as exc:
            self._tell(event, "Cannot show the variant", str(exc))

    def _on_plot_choice(self, event: viser.GuiEvent) -> None:
        if client_of(event) is None:
            return
        results = self.studies.results
        if results is not None:
            self._draw_plot(results)

    def _refresh_list(self) -> None:
        found = self.studies.studies()
        self.pick.options = tuple(found) or (NONE_FOUND,)
        self.status.content = self._status(self.studies.results, len(found))

    @staticmethod
    def _tell(event: Any, title: str, body: str) -> None:
        client = client_of(event)
        if client is not None:
            client.add_notification(title, body, color="red", auto_close_seconds=10.0)

    # -- rendering: everything from app.design_study --------------------------------------------

    @staticmethod
    def _status(results: StudyResults | None, found: int) -> str:
        if results is None:
            return f"<small>{found} studies in the data folder; none open</small>"
        keys = ", ".join(results.keys) or "no varied key"
        return (f"**{results.label}**: {len(results.rows)} variants ({keys}) · from "
                f"{results.source}")

    def render(self) -> None:
        """Show the open study and the variant shown (called on every change)."""
        results = self.studies.results
        if results is not None:
            _set(self.status, "content", self._status(results, 0))
            if results.label in self.pick.options:  # the list shows the study that is open
                _set(self.pick, "value", results.label)
            _set(self.table, "content", table_markdown(results))
            self._choices(self.metric, results.metrics, default_metric(results))
            self._choices(self.over, results.keys, None)
            self._choices(self.variant, results.variants, None)
            _set(self.show_btn, "disabled", False)
            self._draw_plot(results)
        shown = self.studies.shown
        _set(self.hide_btn, "disabled", shown is None)
        _set(self.shown, "content", "" if shown is None else (
            f"<small>Shown beside the arm (lavender, at rest): `{shown.name}` · "
            f"{shown.robot.n_segments} segments · from {shown.study}</small>"))

    @staticmethod
    def _choices(handle: Any, options: tuple[str, ...], first: str | None) -> None:
        """Give a dropdown the study's options, keeping its choice when it is still one."""
        wanted = options or (NO_STUDY,)
        if tuple(handle.options) != wanted:
            keep = handle.value if handle.value in wanted else (first or wanted[0])
            handle.options = wanted
            handle.value = keep
        _set(handle, "disabled", not options)

    def _draw_plot(self, results: StudyResults) -> None:
        metric, over = str(self.metric.value), str(self.over.value)
        if metric not in results.metrics or over not in results.keys:
            self.plot.visible = False
            return
        d = plot_data(results, metric, over)
        series = [uplot.Series(label=over)] + [
            uplot.Series(label=label, stroke=LINE_COLORS[i % len(LINE_COLORS)], width=2,
                         points={"show": True, "size": 7})
            for i, label in enumerate(d.labels)]
        more = f" ({d.omitted} more lines not drawn)" if d.omitted else ""
        title = f"{d.y_label} over {over}{more}"
        data = (d.x, *d.lines)
        old = self.plot.data
        labels = [s.get("label") for s in self.plot.series]
        if (self.plot.visible and self.plot.title == title and len(old) == len(data)
                and labels == [str(s.get("label")) for s in series]
                and all(np.array_equal(a, b, equal_nan=True) for a, b in zip(old, data))):
            return  # drawn already (a variant shown or hidden re-renders the panel)
        with self.app.server.atomic():  # series and data change together in the browser
            self.plot.series = tuple(series)
            self.plot.axes = (uplot.Axis(label=over),
                              uplot.Axis(size=AXIS_SIZE, label=column_unit(metric).unit))
            self.plot.title = title
            self.plot.data = data
            self.plot.visible = True


def _set(handle: Any, name: str, value: Any) -> None:
    """Assign a widget property only when it changes (every assignment is sent to every
    browser)."""
    if getattr(handle, name) != value:
        setattr(handle, name, value)
