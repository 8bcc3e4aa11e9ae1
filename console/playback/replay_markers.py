"""Timeline markers of a recording: phase changes, faults, STOP and operator actions.

:func:`markers_of` picks them from a loaded :class:`~console.recording.recorder.Recording` (events of the
kinds in ``core.labdata.channels.MARKER_KINDS``); the replay panel shows them as slider marks and
jumps to the next / previous one (:func:`next_marker`, :func:`previous_marker`); the HTML export
keeps them as a label in the animated scene and as a list in the page (:func:`markers_html`).
"""

from __future__ import annotations

import dataclasses
import html
from typing import Literal, Sequence

from console.recording.recorder import Recording
from core.labdata.channels import MARKER_KINDS

Category = Literal["phase", "fault", "stop", "action"]
EPS = 1e-6
COLORS = {"phase": "#1c7ed6", "fault": "#c92a2a", "stop": "#e8590c", "action": "#495057"}


@dataclasses.dataclass(frozen=True)
class Marker:
    """One marker: time (s), category, who and the text shown."""

    t: float
    category: Category
    who: str
    text: str

    @property
    def label(self) -> str:
        return f"{self.t:.1f} s · {self.category} · {self.who}: {self.text}"


def _category(kind: str, text: str) -> Category:
    low = text.lower()
    if kind == "fault" or "fault" in low:
        return "fault"
    if kind == "phase":
        return "phase"
    if low.startswith("stop"):
        return "stop"
    return "action"


def markers_of(rec: Recording) -> list[Marker]:
    """The recording's markers in time order."""
    out = []
    for e in rec.events:
        if e.kind not in MARKER_KINDS:
            continue
        text = e.text
        if e.kind == "phase" and isinstance(e.data, dict):
            reason = f" ({e.data['reason']})" if e.data.get("reason") else ""
            text = f"phase {e.data.get('phase')}{reason}"
        elif e.kind == "fault" and isinstance(e.data, dict):
            text = f"fault: {e.data.get('fault')}"
        out.append(Marker(float(e.t), _category(e.kind, text), e.who, text))
    return sorted(out, key=lambda m: m.t)


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


def markers_html(markers: Sequence[Marker]) -> str:
    """The markers as an HTML list (for the exported page; ``data-t`` holds each time)."""
    items = "".join(
        f'<li data-t="{m.t:.3f}" data-category="{m.category}" style="color:{COLORS[m.category]}">'
        f"{html.escape(m.label)}</li>" for m in markers)
    return (f'<details data-testid="run-markers" open style="position:fixed;left:8px;bottom:64px;'
            f"max-height:40vh;max-width:40vw;overflow:auto;z-index:1000;background:#fffe;"
            f'font:12px sans-serif;padding:4px 8px;border-radius:6px">'
            f"<summary>Markers ({len(markers)})</summary><ol>{items}</ol></details>")
