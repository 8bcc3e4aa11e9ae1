"""Display units: millimetres and degrees with a fixed precision, never "-0"."""

from __future__ import annotations

import math

import pytest

from console.units import deg, fmt, mm, mm_value, mm_xyz


@pytest.mark.parametrize("value, decimals, signed, text", [
    (-0.0004, 0, False, "0"),     # rounds to IEEE -0.0
    (-0.0004, 0, True, "+0"),
    (-0.0, 1, False, "0.0"),
    (-0.00004, 1, True, "+0.0"),
    (-0.0006, 0, True, "-1"),     # a real negative keeps its sign
    (0.1234, 1, False, "123.4"),
    (0.25, 0, True, "+250"),
])
def test_mm_never_prints_negative_zero(value, decimals, signed, text):
    assert mm(value, decimals, signed=signed) == text


def test_degrees_and_plain_numbers_and_points():
    assert deg(math.pi / 2) == "90"
    assert deg(-1e-6, 1) == "0.0"
    assert fmt(-1e-9, 2, signed=True) == "+0.00"
    assert mm_xyz((-0.00001, 0.0, 0.46)) == "(0.0, 0.0, 460.0)"
    v = mm_value(-0.00001)
    assert v == 0.0 and math.copysign(1.0, v) == 1.0 and str(v) == "0.0"
