"""core.units: millimetres and degrees for people (fixed decimals, never "-0")."""

from __future__ import annotations

import math

import pytest

from core.units import fmt_deg, fmt_mm, mm_value, mm_xyz, wrap_deg


def test_metres_read_as_millimetres_with_fixed_decimals() -> None:
    assert fmt_mm(0.01234) == "12.3"
    assert fmt_mm(0.01236) == "12.4"
    assert fmt_mm(-0.25) == "-250.0"
    assert fmt_mm(0.4, 0) == "400"
    assert fmt_mm(0.0001234, 3) == "0.123"
    assert fmt_mm(0.012, sign=True) == "+12.0"
    assert fmt_mm(-0.012, sign=True) == "-12.0"


@pytest.mark.parametrize("tiny", [-0.0, -1e-9, -0.00004, -4.9e-5])
def test_a_negative_length_that_rounds_to_zero_is_zero(tiny: float) -> None:
    assert fmt_mm(tiny) == "0.0"
    assert fmt_mm(tiny, 0) == "0"
    assert fmt_mm(tiny, sign=True) == "+0.0"
    assert fmt_mm(-0.00006) == "-0.1"  # not zero: keeps its sign


def test_radians_read_as_degrees() -> None:
    assert fmt_deg(math.pi / 2) == "90.0"
    assert fmt_deg(math.radians(12.34), 2) == "12.34"
    assert fmt_deg(-math.radians(0.04)) == "0.0"  # no "-0.0"
    assert fmt_deg(math.radians(400.0)) == "400.0"  # a bend is not wrapped unless asked
    assert fmt_deg(math.radians(5.0), sign=True) == "+5.0"


def test_headings_wrap_to_minus_180_exclusive_180_inclusive() -> None:
    assert wrap_deg(3 * math.pi / 2) == pytest.approx(-90.0)
    assert wrap_deg(-math.pi) == pytest.approx(180.0)
    assert fmt_deg(math.radians(400.0), wrap=True) == "40.0"
    assert fmt_deg(-math.pi, wrap=True) == "180.0"
    assert fmt_deg(math.radians(-179.99), wrap=True) == "180.0"  # rounds onto the -180 end
    assert fmt_deg(math.radians(-179.9), wrap=True, sign=True) == "-179.9"
    assert fmt_deg(math.radians(359.99), wrap=True) == "0.0"


def test_bad_decimals_and_non_finite_values() -> None:
    with pytest.raises(ValueError, match="decimals"):
        fmt_mm(0.1, -1)
    assert fmt_mm(math.nan) == "nan"
    assert fmt_mm(math.inf, sign=True) == "+inf"


@pytest.mark.parametrize("value, decimals, sign, text", [
    (-0.0004, 0, False, "0"),     # rounds to IEEE -0.0
    (-0.0004, 0, True, "+0"),
    (-0.0, 1, False, "0.0"),
    (-0.00004, 1, True, "+0.0"),
    (-0.0006, 0, True, "-1"),     # a real negative keeps its sign
    (0.1234, 1, False, "123.4"),
    (0.25, 0, True, "+250"),
])
def test_clamp_notes_never_print_negative_zero(value: float, decimals: int, sign: bool,
                                               text: str) -> None:
    assert fmt_mm(value, decimals, sign=sign) == text


def test_points_and_gui_numbers_in_millimetres() -> None:
    assert fmt_deg(math.pi / 2, 0) == "90"
    assert fmt_deg(-1e-6, 1) == "0.0"
    assert mm_xyz((-0.00001, 0.0, 0.46)) == "(0.0, 0.0, 460.0)"
    v = mm_value(-0.00001)
    assert v == 0.0 and math.copysign(1.0, v) == 1.0 and str(v) == "0.0"
    assert mm_value(0.01236) == 12.4
