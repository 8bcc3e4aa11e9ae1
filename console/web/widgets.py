"""The few widget facts viser 1.1.1 keeps private that the console's panels need, in one place.

A panel may need a widget's DOM id (to style it) or to set a slider's marks after it was built;
viser 1.1.1 has no public way to do either (``handle._impl.uuid``; ``marks`` is an argument of
``add_slider`` only, kept in the private ``_marks`` prop as ``viser._messages.GuiSliderMark``).
Panels call these functions instead, so a viser upgrade is checked here alone.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any


def widget_id(handle: Any) -> str:
    """The id viser gives a GUI widget (its element's ``id`` in the page)."""
    return str(handle._impl.uuid)


def set_slider_marks(slider: Any, values: Iterable[float]) -> None:
    """Show unlabelled marks at ``values`` below ``slider`` (every browser, at once)."""
    from viser._messages import GuiSliderMark

    slider._marks = tuple(GuiSliderMark(value=float(v), label=None) for v in values)


def slider_marks(slider: Any) -> tuple[float, ...]:
    """The values of the marks ``slider`` shows (empty when it has none)."""
    return tuple(float(m.value) for m in (slider._marks or ()))
