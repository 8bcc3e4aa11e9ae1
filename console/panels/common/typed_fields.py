"""Keeps a panel's echo of its state from overwriting a field the operator has just typed.

viser stores a browser's new value in the handle before the field's callback runs (in a thread
pool). A panel that shows its state in the same fields (the object's x, y, r; the tip target)
can write the echo of an earlier edit in between -- typing x, then y: the answer to x carries the
old y -- and the callback of y then reads the old y back (a CI run lost a typed target y so).
:class:`TypedFields` remembers what each field held when the panel last wrote or read it; a
field that differs holds a value typed since, which its own callback takes, so the echo skips it.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable, Sequence
from typing import Any


class TypedFields:
    """The number inputs of one panel that both take typed values and show the panel's state.

    Args:
        handles: The GUI number handles (viser ``GuiNumberHandle``-like: ``.value``).
        tolerance: A shown value within this of the field's is not written (no flicker).
    """

    def __init__(self, handles: Sequence[Any], tolerance: float = 0.05) -> None:
        self._handles = list(handles)
        self._tolerance = tolerance
        self._lock = threading.RLock()  # (a value written may call back into read())
        self._known = {id(h): float(h.value) for h in self._handles}

    def read(self, handles: Iterable[Any] | None = None) -> list[float]:
        """The values of ``handles`` (default: all), from now on the panel's own (callback)."""
        chosen = self._handles if handles is None else list(handles)
        with self._lock:
            values = [float(h.value) for h in chosen]
            self._known.update((id(h), v) for h, v in zip(chosen, values))
            return values

    def show(self, values: Iterable[float], handles: Iterable[Any] | None = None,
             typed_too: bool = False) -> None:
        """Write ``values`` to ``handles`` (default: all), except a field typed since the panel
        last wrote or read it; ``typed_too``: every field (a refused or bad edit goes back)."""
        chosen = self._handles if handles is None else list(handles)
        with self._lock:
            for h, value in zip(chosen, values):
                current = float(h.value)
                if not typed_too and current != self._known[id(h)]:
                    continue
                if not abs(current - value) <= self._tolerance:  # (a NaN typed: written)
                    h.value = current = float(value)
                self._known[id(h)] = current
