"""What a browser may store in a widget: the right type, finite, within the widget's bounds.

:func:`validate_value` is the value check of ``console.web.client_guard`` (see there for where it
sits and why), kept apart so it can be read and tested on its own; :func:`check_fields` is the
guard's first look at any message's fields (numbers finite, sizes and nesting bounded).
:class:`GuardLimits` holds every limit the guard applies to one browser.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any


class Refused(ValueError):
    """A value a widget must not take; the message says why, for the user."""


class OutOfBounds(Refused):
    """A number outside the widget's min / max. A browser sends these while someone types
    (each keystroke: "0" on the way to "0.03"), and clamps the field when it loses focus; so the
    value is only not stored -- no value sent back, which would overwrite the typing."""


@dataclasses.dataclass(frozen=True)
class GuardLimits:
    """What one browser may send.

    Attributes:
        max_message_bytes: Largest frame accepted (a file upload part is 512 KiB).
        rate: Messages per second a client may send on average ...
        burst: ... and at once (a slider drag sends ~60 per second, camera moves as many).
        flood_drops: Messages dropped (over the rate, or not accepted) within ``flood_window`` s
            after which the client is disconnected.
        flood_window: Seconds over which drops are counted.
        max_text: Longest text a text field takes (characters).
        max_string: Longest string anywhere else in a message.
        max_items: Longest list / dict anywhere in a message.
        max_abs: Largest magnitude of any number without bounds of its own.
        max_upload_bytes: Largest file a browser may upload.
        log_every: Seconds between two log lines of the same kind for one client.
    """

    max_message_bytes: int = 1024 * 1024
    rate: float = 100.0
    burst: float = 200.0
    flood_drops: int = 1000
    flood_window: float = 10.0
    max_text: int = 256
    max_string: int = 4096
    max_items: int = 256
    max_abs: float = 1e9
    max_upload_bytes: int = 1024 * 1024
    log_every: float = 5.0


def short(value: Any, limit: int = 80) -> str:
    """``repr(value)`` cut to ``limit`` characters, for log lines (a 10 MB value stays short)."""
    if isinstance(value, (bytes, bytearray, memoryview)):
        return f"<{len(value)} bytes>"
    if isinstance(value, str) and len(value) > limit:
        return repr(value[:limit]) + f"... ({len(value)} chars)"
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


def _number(value: Any, what: str, limits: GuardLimits) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise Refused(f"{what} must be a number, got {short(value, 40)}")
    if not math.isfinite(value):
        raise Refused(f"{what} must be finite, got {value}")
    if abs(value) > limits.max_abs:
        raise Refused(f"{what} is out of range ({short(value, 40)})")
    return value


def _bounded(value: float, lo: Any, hi: Any, integer: bool) -> float | int:
    if lo is not None and value < lo:
        raise OutOfBounds(f"{value:g} is below the minimum {lo:g}")
    if hi is not None and value > hi:
        raise OutOfBounds(f"{value:g} is above the maximum {hi:g}")
    if integer:
        if value != int(value):
            raise Refused(f"{value:g} is not a whole number")
        return int(value)
    return value


def check_fields(value: Any, limits: GuardLimits, depth: int, skip_bytes: bool,
                 text_limit: int) -> None:
    """Every number finite and moderate, strings / containers bounded, nesting shallow (any
    message's fields, before its type's own check).

    Raises:
        Refused: what is wrong, for the log.
    """
    lim = limits
    if depth > 6:
        raise Refused("nested too deep")
    if isinstance(value, bool) or value is None:
        return
    if isinstance(value, float) or isinstance(value, int):
        if abs(value) > lim.max_abs or not math.isfinite(value):  # (abs first: big ints)
            raise Refused(f"number out of range: {short(value)}")
    elif isinstance(value, str):
        if len(value) > text_limit:
            raise Refused(f"string of {len(value)} characters")
    elif isinstance(value, (bytes, bytearray)):
        if not skip_bytes:
            raise Refused("unexpected bytes")
    elif isinstance(value, dict):
        if len(value) > lim.max_items:
            raise Refused(f"{len(value)} items")
        for k, v in value.items():
            check_fields(k, lim, depth + 1, skip_bytes, lim.max_string)
            check_fields(v, lim, depth + 1, skip_bytes, text_limit)
    elif isinstance(value, (list, tuple)):
        if len(value) > lim.max_items:
            raise Refused(f"{len(value)} items")
        for v in value:
            check_fields(v, lim, depth + 1, skip_bytes, text_limit)
    else:
        raise Refused(f"unexpected {type(value).__name__}")


def validate_value(handle: Any, value: Any, limits: GuardLimits) -> Any:
    """``value`` as the widget ``handle`` may store it.

    Raises:
        Refused: the reason, for the user (type, finiteness, bounds, options, length).
    """
    impl = handle._impl
    props = impl.props
    kind = type(handle).__name__
    current = impl.value
    if kind == "GuiUploadButtonHandle":  # files come as FileTransfer messages, never as a value
        raise Refused("an upload button takes files, not values")
    if impl.is_button and kind != "GuiButtonGroupHandle":  # a group sends the option's name
        if value is not True:
            raise Refused("a button sends true")
        return True
    if kind in ("GuiNumberHandle", "GuiSliderHandle"):
        v = _number(value, "the value", limits)
        return _bounded(v, props.min, props.max, isinstance(current, int))
    if kind == "GuiMultiSliderHandle":
        if not isinstance(value, (list, tuple)) or len(value) != len(current):
            raise Refused(f"expected {len(current)} numbers")
        integer = bool(current) and isinstance(current[0], int)
        return tuple(_bounded(_number(v, "each value", limits), props.min, props.max, integer)
                     for v in value)
    if kind in ("GuiVector2Handle", "GuiVector3Handle"):
        n = 2 if kind == "GuiVector2Handle" else 3
        if not isinstance(value, (list, tuple)) or len(value) != n:
            raise Refused(f"expected {n} numbers")
        lo = props.min if props.min is not None else (None,) * n
        hi = props.max if props.max is not None else (None,) * n
        return tuple(float(_bounded(_number(v, "each component", limits), a, b, False))
                     for v, a, b in zip(value, lo, hi))
    if kind in ("GuiRgbHandle", "GuiRgbaHandle"):
        n = 3 if kind == "GuiRgbHandle" else 4
        if not isinstance(value, (list, tuple)) or len(value) != n:
            raise Refused(f"expected {n} colour components")
        return tuple(int(_bounded(_number(v, "a colour component", limits), 0, 255, True))
                     for v in value)
    if kind == "GuiCheckboxHandle":
        if not isinstance(value, bool):
            raise Refused(f"a checkbox is true or false, got {short(value, 40)}")
        return value
    if kind == "GuiTextHandle":
        if not isinstance(value, str):
            raise Refused(f"expected text, got {short(value, 40)}")
        if len(value) > limits.max_text:
            raise Refused(f"text of {len(value)} characters (at most {limits.max_text})")
        return value
    if kind in ("GuiDropdownHandle", "GuiButtonGroupHandle"):
        if not isinstance(value, str) or value not in tuple(props.options):
            raise Refused(f"{short(value, 40)} is not one of the options")
        return value
    raise Refused(f"{kind} takes no value from browsers")
