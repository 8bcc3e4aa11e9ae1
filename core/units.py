"""Lengths and angles as people read them: SI inside, millimetres and degrees on screen.

Pure functions shared by the console's panels and the command-line tables (``core`` may not
import ``console``, so this lives here). Each returns the number only, with a fixed number of
decimals and never ``-0.0``: the unit belongs in the label or column header ("x (mm)").
"""

from __future__ import annotations

import math
from collections.abc import Iterable

MM_PER_M = 1000.0


def _fixed(value: float, decimals: int, sign: bool) -> str:
    """``value`` with ``decimals`` decimals; a result that rounds to zero is ``0``, not ``-0``."""
    if decimals < 0:
        raise ValueError(f"decimals must be >= 0, got {decimals}")
    if not math.isfinite(value):
        return f"{value:+}" if sign and not math.isnan(value) else f"{value}"
    text = f"{value:{'+' if sign else ''}.{decimals}f}"
    digits = text.lstrip("+-")
    if text[0] == "-" and not digits.strip("0."):  # "-0.0" after rounding
        return ("+" if sign else "") + digits
    return text


def fmt_mm(x_m: float, decimals: int = 1, *, sign: bool = False) -> str:
    """A length given in metres as millimetres: ``fmt_mm(0.01234) == "12.3"``.

    Args:
        x_m: Length (m).
        decimals: Decimals shown (0.1 mm by default: the arm is not positioned finer).
        sign: Always show the sign (``+12.3``), for coordinates.
    """
    return _fixed(float(x_m) * MM_PER_M, decimals, sign)


def wrap_deg(theta_rad: float) -> float:
    """An angle given in radians, in degrees wrapped to (-180, 180]."""
    deg = math.degrees(float(theta_rad)) % 360.0
    return deg - 360.0 if deg > 180.0 else deg


def fmt_deg(theta_rad: float, decimals: int = 1, *, sign: bool = False,
            wrap: bool = False) -> str:
    """An angle given in radians as degrees: ``fmt_deg(math.pi / 2) == "90.0"``.

    Args:
        theta_rad: Angle (rad).
        decimals: Decimals shown.
        sign: Always show the sign (``+90.0``).
        wrap: Wrap to (-180, 180] first (headings); without it a 400° bend stays 400°.
    """
    value = wrap_deg(theta_rad) if wrap else math.degrees(float(theta_rad))
    text = _fixed(value, decimals, sign)
    if wrap and text.lstrip("+") == _fixed(-180.0, decimals, False):
        return _fixed(180.0, decimals, sign)  # -179.99 rounds to -180: show the (-180, 180] end
    return text


def mm_value(x_m: float, decimals: int = 1) -> float:
    """A length given in metres as a millimetre number for a GUI input, rounded, never -0.0."""
    v = round(float(x_m) * MM_PER_M, decimals)
    return 0.0 if v == 0 else v  # -0.0 == 0: normalised to +0.0


def mm_xyz(point_m: Iterable[float], decimals: int = 1) -> str:
    """A point given in metres as ``"(x, y, z)"`` in millimetres, without the unit."""
    return "(" + ", ".join(fmt_mm(float(v), decimals) for v in point_m) + ")"
