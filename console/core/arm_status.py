"""Whether the screen may believe the loop's published view: the header's Phase and Link rule.

The arm's 100 Hz loop runs in its own process and publishes a view (phase, arming, link) a few
dozen times a second. What the header says about the arm must come from that view *with its
age*: a dead loop process, or one that has not published for :data:`STALE_AFTER_S`, leaves the
last view behind, and that view may still say "approach · ARMED · active". :func:`header_fields`
decides, from the loop's news (:class:`LoopNews`: alive, its failure, the view's age), whether
the arm's own wording of the view may be shown, or what to say instead (in the fault tone,
never ARMED, the link "unknown"). Pure: no viser, no clock, no threads; the console's
:class:`console.panels.common.loop_header.LoopHeader` feeds it and pushes the result to the header.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable, Literal, Optional, Tuple

from hw_bridge.loop_process import STALE_VIEW_S

Tone = Literal["ok", "busy", "warn", "fault"]  # a header field's colour (console.panels.common.header)
STALE_AFTER_S = STALE_VIEW_S  # a view older than this is not the arm's state any more
Field = Tuple[str, Optional[Tone]]  # (text, tone) of one header field
UNKNOWN_LINK: Field = ("unknown", "fault")


@dataclasses.dataclass(frozen=True)
class LoopNews:
    """What the console knows about the loop process, read at one moment.

    Attributes:
        started: Whether a loop process was ever spawned (an extensible arm on the in-process
            mock may start later).
        alive: Whether it runs now.
        failure: Why it died or failed to start (None: no reason known).
        age: Seconds since its newest view arrived (``math.inf`` before the first).
    """

    started: bool
    alive: bool
    failure: str | None
    age: float


def loop_trouble(news: LoopNews) -> str | None:
    """Why the newest view is not the arm's state now, in words (None: it is fresh)."""
    if not news.started:
        return "control loop not started"
    if not news.alive:
        why = (news.failure or "the process ended").removeprefix("the control process was ")
        return f"control loop not running: {why}"
    if news.failure:  # alive but its start-up failed (it reported why)
        return f"control loop failed: {news.failure}"
    if math.isinf(news.age):
        return "starting the control loop…"
    if news.age > STALE_AFTER_S:
        return f"no news from the control loop for {news.age:.1f} s"
    return None


def header_fields(news: LoopNews, view: Any, phase_of: Callable[[Any], Field],
                  link_of: Callable[[Any], Field]) -> tuple[Field, Field]:
    """The header's (Phase, Link) fields.

    Args:
        news: The loop process's state and the newest view's age.
        view: The newest published view (None before the first).
        phase_of: The arm's wording of a fresh view's phase (may say ARMED).
        link_of: The arm's wording of a fresh view's link (may say active).

    Returns:
        The arm's own wording while the view is fresh; else the trouble in the fault tone as
        the phase (a loop that is only starting: the busy tone) and the link "unknown".
    """
    trouble = loop_trouble(news)
    if trouble is None and view is not None:
        return phase_of(view), link_of(view)
    if trouble is None:  # (fresh news without a view cannot happen; say nothing untrue)
        trouble = "starting the control loop…"
    starting = news.alive and not news.failure and math.isinf(news.age)
    return (trouble, "busy" if starting else "fault"), UNKNOWN_LINK
