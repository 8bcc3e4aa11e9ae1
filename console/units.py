"""Display formatting of SI values in the console's units (mm, degrees), never "-0".

Inside, everything is SI (m, rad); panels show millimetres and degrees. Rounding a small
negative value (-0.0004 m to whole millimetres) gives IEEE negative zero, which Python prints
as "-0": these helpers normalise it to "0" (or "+0" when a sign is asked for).
"""

from __future__ import annotations

import math
from collections.abc import Iterable


def _rounded(value: float, decimals: int) -> float:
    v = round(float(value), decimals)
    return 0.0 if v == 0 else v  # -0.0 == 0: normalised to +0.0


def fmt(value: float, decimals: int = 1, *, signed: bool = False) -> str:
    """``value`` with ``decimals`` places (``+`` sign if ``signed``), never negative zero."""
    v = _rounded(value, decimals)
    return f"{v:+.{decimals}f}" if signed else f"{v:.{decimals}f}"


def mm(metres: float, decimals: int = 1, *, signed: bool = False) -> str:
    """Metres as millimetre text without the unit: ``mm(-0.0004, 0)`` -> ``"0"``."""
    return fmt(float(metres) * 1e3, decimals, signed=signed)


def deg(radians: float, decimals: int = 0, *, signed: bool = False) -> str:
    """Radians as degree text without the unit."""
    return fmt(math.degrees(float(radians)), decimals, signed=signed)


def mm_value(metres: float, decimals: int = 1) -> float:
    """Metres as a millimetre number for a GUI input, rounded, never -0.0."""
    return _rounded(float(metres) * 1e3, decimals)


def mm_xyz(metres: Iterable[float], decimals: int = 1) -> str:
    """A point (m) as ``"(x, y, z)"`` in millimetres, without the unit."""
    return "(" + ", ".join(mm(float(v), decimals) for v in metres) + ")"
