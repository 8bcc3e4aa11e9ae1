"""Control panel (soft arm): the run's progress bar and line, so the operator sees how far the
arm is and how long it still takes (issue 31.3).

While the arm runs a task: a progress bar (viser's ``add_progress_bar``, 0-100) and one line
"Object 2 (object 2 of 3) · waypoint 3 of 9 · ≈ 42 s left", both from the
:class:`console.core.run_state.RunView` the Control panel reads from the loop's published view
(the remaining time is :mod:`core.control.run_estimate`'s estimate from the plan the arm runs).
Hidden when no task runs. The estimate before Execute is on the target line
(:mod:`console.panels.soft_arm.control_execute`).
"""

from __future__ import annotations

import html
from typing import Any

from console.core.run_state import RunView


def progress_html(run: RunView | None) -> str:
    """The progress line (``data-testid="run-progress"`` with the waypoint, object and seconds
    left for tests); empty when no task runs."""
    if run is None:
        return ""
    wp = "" if run.waypoint is None else str(run.waypoint + 1)
    n = "" if run.plan is None else str(run.plan.n)
    left = "" if run.row_remaining_s is None else f"{run.row_remaining_s:.1f}"
    obj = "" if run.index is None else str(run.index + 1)
    what = run.object_text()
    parts = [html.escape(what)] if what else []
    parts += [html.escape(run.waypoint_text()), html.escape(run.time_text())]
    return (f'<div data-testid="run-progress" data-waypoint="{wp}" data-waypoints="{n}" '
            f'data-object="{obj}" data-objects="{run.count}" data-left="{left}" '
            f'data-fraction="{run.fraction:.3f}" style="font-size:0.85em">'
            f"<b>Running:</b> {' · '.join(parts)}</div>")


class ProgressControls:
    """The progress bar and line in the Control panel (see the module docstring)."""

    def __init__(self, gui: Any) -> None:
        self.bar = gui.add_progress_bar(0.0, visible=False, animated=True)
        self.line = gui.add_html("", visible=False)

    def show(self, run: RunView | None) -> None:
        """Show ``run``'s progress (None hides both)."""
        text = progress_html(run)
        if text != self.line.content:
            self.line.content = text
        self.line.visible = self.bar.visible = run is not None
        if run is not None:
            value = round(100.0 * min(max(run.fraction, 0.0), 1.0), 1)
            if value != self.bar.value:
                self.bar.value = value
