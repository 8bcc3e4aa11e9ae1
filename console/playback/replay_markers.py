"""Timeline markers of a recording: phase changes, faults, STOP, link changes, operator actions.

:func:`markers_of` makes one marker per sentence of the recording's log
(:func:`console.playback.replay_log.sentences`: "12.4 s  Armed", "30.1 s  Phase: approach →
grasp"); the replay panel shows them as slider marks and its log, and jumps to the next /
previous one (:func:`next_marker`, :func:`previous_marker`); the HTML export keeps them as a label
in the animated scene and as a collapsible list beside the 3D view (:func:`markers_html`: the
page becomes a row, the view and the list, so the list never covers the arm).
"""

from __future__ import annotations

import dataclasses
import html
from typing import Sequence

from console.playback.replay_log import Category, sentences
from console.recording.recorder import Recording

EPS = 1e-6
COLORS = {"phase": "#1c7ed6", "fault": "#c92a2a", "stop": "#e8590c", "action": "#495057",
          "link": "#0b7285"}
SIDE_WIDTH = "18rem"  # the exported page's marker list, beside the view (open)


@dataclasses.dataclass(frozen=True)
class Marker:
    """One marker: time (s), category, who and the sentence shown."""

    t: float
    category: Category
    who: str
    text: str

    @property
    def label(self) -> str:
        """The log line: time and sentence ("12.4 s  Armed")."""
        return f"{self.t:.1f} s  {self.text}"


def markers_of(rec: Recording) -> list[Marker]:
    """The recording's markers (its log's sentences) in time order."""
    return [Marker(s.t, s.category, s.who, s.text) for s in sentences(rec.events)]


def next_marker(markers: Sequence[Marker], t: float) -> Marker | None:
    """The first marker after ``t`` (None if there is none)."""
    return next((m for m in markers if m.t > t + EPS), None)


def previous_marker(markers: Sequence[Marker], t: float) -> Marker | None:
    """The last marker before ``t`` (None if there is none)."""
    return next((m for m in reversed(markers) if m.t < t - EPS), None)


def current_marker(markers: Sequence[Marker], t: float) -> tuple[int, Marker] | None:
    """Index and marker of the last marker at or before ``t``."""
    found = None
    for i, m in enumerate(markers):
        if m.t > t + EPS:
            break
        found = (i, m)
    return found


# The exported page (viser's client: <body><div id="root"> filling the window) becomes a row:
# the view shrinks to what the list leaves (the canvas follows its container), the list is a
# <details> beside it (closed: only its summary, the view takes the rest); on a narrow screen
# the list goes under the view instead. Never fixed or absolute: nothing is drawn over the view.
SIDE_CSS = (
    "html body{display:flex!important;flex-direction:row;height:100%;margin:0}"
    "html body>#root{flex:1 1 0!important;min-width:0!important;width:auto!important;"
    "height:100%!important}"
    "#run-markers{flex:0 0 auto;position:static;box-sizing:border-box;height:100%;"
    f"max-width:{SIDE_WIDTH};overflow:auto;background:#fff;border-left:1px solid #ccc;"
    "font:12px sans-serif;padding:4px 8px;margin:0}"
    "#run-markers:not([open]){width:auto}"
    "#run-markers[open]{width:" + SIDE_WIDTH + "}"
    "#run-markers summary{cursor:pointer;font-weight:600;white-space:nowrap}"
    "#run-markers ol{padding-left:1.4em;margin:4px 0}"
    "#run-markers li{white-space:pre-wrap;margin:2px 0}"
    "@media (max-width:600px){html body{flex-direction:column}"
    "#run-markers,#run-markers[open]{width:auto;max-width:none;height:auto;max-height:35%;"
    "border-left:0;border-top:1px solid #ccc}}")


def markers_html(markers: Sequence[Marker]) -> str:
    """The markers as a collapsible list (``<details id="run-markers">``, open; ``data-t``
    holds each time) to put after viser's ``#root`` in the exported page's ``<body>``."""
    items = "".join(
        f'<li data-t="{m.t:.3f}" data-category="{m.category}" style="color:{COLORS[m.category]}">'
        f"{html.escape(m.label)}</li>" for m in markers)
    return (f'<details id="run-markers" data-testid="run-markers" open>'
            f"<summary>Log · {len(markers)} markers</summary><ol>{items}</ol></details>")


def with_markers(page: str, markers: Sequence[Marker]) -> str:
    """An exported page (viser's ``as_html``) with the markers as a side list beside its view:
    :data:`SIDE_CSS` at the end of ``<head>``, :func:`markers_html` at the end of ``<body>``
    (the page unchanged without markers or without those tags)."""
    body = page.rfind("<body")
    head = page.rfind("</head>", 0, max(body, 0))  # the real one: the last before <body>
    end = page.rfind("</body>")
    if not markers or body < 0 or head < 0 or end < body:
        return page
    style = f'<style id="run-markers-layout">{SIDE_CSS}</style>'
    return page[:head] + style + page[head:end] + markers_html(markers) + page[end:]
