"""Control panel (soft arm): "Clear table into bin" takes every object on the table to the bin.

Issue #17.3 in the console. The Objects panel holds the objects and the bin the operator placed
by clicking (``console.core.table_bin``); the button sends them, in the Objects panel's order, as one
:class:`~hw_bridge.commands.RunRow` to the control process, whose stack takes them one after
another (:class:`core.control.row_stack.RowControlStack`; an object that fails is recorded with
its reason and the row goes on; the header's STOP ends the row and skips the rest). While the
row runs, the header's phase field and the panel say "object k of N: <phase>"; afterwards the
panel lists every object as released, failed (reason) or skipped (reason). A released object
is taken off the table (the Objects panel), so the scene stays true.

Refused with what to do, sending nothing: a viewer (operator only), a disarmed arm ("Arm first
(press Arm)", as Execute), no bin ("Place a bin first"), no objects, an object the Objects
panel would not accept. :class:`RowControls` is built by the Control panel inside its folder
and shown from its refresh; the text is built by pure functions below.
"""

from __future__ import annotations

import dataclasses
import html
import itertools
from typing import Any

import viser

from console.panels.common.header import Tone
from console.panels.common.base import operator_only
from console.panels.soft_arm.control_text import IDLE_PHASES
from console.core.table_scene import validate_object
from console.core.run_state import row_position
from console.panels.common.events import client_of
from hw_bridge.soft_arm_process import ROW_ARM_FIRST, ControlView

NO_BIN = ("Place a bin first: at the top of Operate choose 'Table click places: Bin' and "
          "click on the table where it stands.")
NO_OBJECTS = "No objects on the table to clear into the bin: place some in the Objects panel."
KEEP_ROWS = 8  # rows taken whose names the panel keeps (a report names the newest)
STATUS_WORDS = {"released": "released", "failed": "failed", "skipped": "skipped"}


@dataclasses.dataclass(frozen=True)
class SentRow:
    """A row this console sent: its id, the objects' names in order, and the bin."""

    row_id: int
    names: tuple[str, ...]
    bin_text: str


def row_header_phase(view: ControlView, sent: SentRow | None) -> tuple[str, Tone] | None:
    """The header's phase field while a row runs ("object 2 of 3: approach · waypoint 4 of 9 ·
    ARMED"); None when no row runs (the Control panel's own phase text applies)."""
    report, c = view.row, view.snapshot.control
    if report is None or not report.running or report.current is None or c is None:
        return None
    wp = ""
    if c.n_waypoints and c.phase == "approach":
        wp = f" · waypoint {c.waypoint + 1} of {c.n_waypoints}"
    armed = "ARMED" if c.armed else "disarmed"
    return (f"object {row_position(report) + 1} of {report.n}: {c.phase}{wp} · {armed}",
            "busy")


def _name(sent: SentRow | None, report: Any, index: int) -> str:
    if sent is not None and sent.row_id == report.row_id and index < len(sent.names):
        return sent.names[index]
    return f"object {index + 1}"


def row_html(view: ControlView | None, sent: SentRow | None) -> str:
    """The panel's row line: progress while running, then one line per object
    (``data-testid="row-status"`` with ``data-state``, ``data-released``, ``data-n``; each
    object's ``li`` has ``data-status``)."""
    report = None if view is None else view.row
    if report is None:
        return ('<div data-testid="row-status" data-state="" data-released="" data-n="">'
                "<small>Clear table into bin: takes every object in the Objects panel to the "
                "bin placed there, one after another.</small></div>")
    head = (f'<div data-testid="row-status" data-state="{report.state}" '
            f'data-released="{report.released}" data-n="{report.n}">')
    c = None if view is None else view.snapshot.control
    if report.running and report.current is not None:
        phase = "" if c is None else f": {html.escape(c.phase)}"
        name = html.escape(_name(sent, report, report.current))
        where = f" into the {html.escape(sent.bin_text)}" if sent is not None else ""
        taken = row_position(report) + 1  # in the order taken, like the header's
        body = (f"<b>Clearing the table{where}:</b> object {taken} of {report.n} "
                f"({name}){phase} · {report.released} released so far")
    else:
        how = "done" if report.state == "done" else f"stopped ({html.escape(report.reason or '')})"
        body = f"<b>Row {how}:</b> {report.released} of {report.n} released"
    items = []
    for o in report.outcomes:
        why = "" if o.reason is None else f" ({html.escape(o.reason)})"
        items.append(f'<li data-status="{o.status}">{html.escape(_name(sent, report, o.index))}: '
                     f"{STATUS_WORDS[o.status]}{why}</li>")
    listing = (f'<ul style="margin:0;padding-left:1.2em">{"".join(items)}</ul>' if items else "")
    return f"{head}<small>{body}{listing}</small></div>"


class RowControls:
    """The Control panel's "Clear table into bin" button and row status (see the module
    docstring). ``panel`` is the Control panel (its ``ctl``, ``app``, ``is_disarmed``,
    ``refuse_action`` and ``report_done``)."""

    def __init__(self, panel: Any) -> None:
        self.panel, self.app = panel, panel.app
        gui = panel.gui
        self.button = gui.add_button(
            "Clear table into bin", icon=viser.Icon.TRASH,
            hint="takes every object in the Objects panel to the bin placed there, one after "
                 "another (a failed object is skipped with its reason; STOP ends the row); "
                 "arm first")
        self.status = gui.add_html(row_html(None, None))
        self.button.on_click(operator_only(self._clear, panel=panel,
                                           action="clear the table into the bin"))
        self.rows: dict[int, SentRow] = {}  # rows this console sent, by id (newest few)
        self._ids = itertools.count(1)
        self._taken_off: set[tuple[int, int]] = set()  # (row id, index) removed from the table
        self._recorded_end: int | None = None  # the row whose end went into the recording

    # -- the button (operator only) ------------------------------------------------------------
    def _clear(self, event: Any) -> None:
        if self.panel.is_disarmed():  # arming is the operator's own act (issue 19.3)
            self.panel.refuse_action(event, "Arm first", ROW_ARM_FIRST)
            return
        view = self.app.soft_arm_grasp().view()
        if view.bin is None:
            self.panel.refuse_action(event, "Place a bin first", NO_BIN)
            return
        if not view.objects:
            self.panel.refuse_action(event, "Nothing to clear", NO_OBJECTS)
            return
        try:
            for o in view.objects:
                validate_object(o, self.app.robot)
        except ValueError as exc:
            self.panel.refuse_action(event, "Refused", str(exc))
            return
        sent = SentRow(next(self._ids), tuple(o.name for o in view.objects),
                       view.bin.describe())
        # By id: a second press while this row runs (a double click) is refused by the control
        # process and must not take the running row's names from it.
        self.rows[sent.row_id] = sent
        for old in sorted(self.rows)[:-KEEP_ROWS]:
            del self.rows[old]
        self.panel.execute.target = None
        ctl = self.panel.ctl
        fut = self.app.core.start_motion(lambda: ctl.run_row(
            sent.row_id, [(o.x, o.y, o.r) for o in view.objects], (view.bin.x, view.bin.y),
            view.bin.kappa, view.bin.kappa_right, tuple(view.obstacles), float(view.clearance)))
        fut.add_done_callback(lambda f: self._sent(event, sent, f))

    def _sent(self, event: Any, sent: SentRow, fut: Any) -> None:
        """The control process took the row (say so) or refused it (the operator is told why)."""
        if fut.exception() is not None:
            self.rows.pop(sent.row_id, None)
            self.panel.report_done(event, fut)
            return
        what = f"{len(sent.names)} object{'s' if len(sent.names) != 1 else ''} into the " \
               f"{sent.bin_text}"
        client = client_of(event)
        if client is not None:
            client.add_notification("Clear table into bin", f"Taking {what}, one after another.",
                                    color="blue", auto_close_seconds=6.0)
        self.app.recorder.action(f"clear table into bin: {what}", client)

    def sent_for(self, report: Any) -> SentRow | None:
        """The row this console sent that ``report`` is about (None: another console's)."""
        return None if report is None else self.rows.get(report.row_id)

    # -- display (the Control panel's refresh) -------------------------------------------------
    def header(self, view: ControlView) -> tuple[str, Tone] | None:
        return row_header_phase(view, self.sent_for(view.row))

    def show(self, view: ControlView) -> None:
        text = row_html(view, self.sent_for(view.row))
        if text != self.status.content:
            self.status.content = text
        c = view.snapshot.control
        report = view.row
        running = report is not None and report.running
        busy = c is not None and c.phase not in IDLE_PHASES + ("settling",)
        self.button.disabled = running or busy
        self._take_off_released(report)
        self._record_end(report)

    def _record_end(self, report: Any) -> None:
        """Once per row: its end and every object's outcome into the recording."""
        if report is None or report.running or report.row_id == self._recorded_end:
            return
        self._recorded_end = report.row_id
        outcomes = "; ".join(
            f"{_name(self.sent_for(report), report, o.index)}: {o.status}"
            + ("" if o.reason is None else f" ({o.reason})") for o in report.outcomes)
        self.app.recorder.action(f"row {report.state}: {report.released} of {report.n} "
                                 f"released -- {outcomes}", None)

    def _take_off_released(self, report: Any) -> None:
        """Remove every object this console sent that the row released from the table."""
        sent, session = self.sent_for(report), self.app.soft_arm_grasp()
        if report is None or sent is None or sent.row_id != report.row_id:
            return
        names = {o.name for o in session.view().objects}
        for o in report.outcomes:
            key = (report.row_id, o.index)
            if o.status != "released" or key in self._taken_off or o.index >= len(sent.names):
                continue
            self._taken_off.add(key)
            if sent.names[o.index] in names:
                session.remove(sent.names[o.index])
