"""core.units: millimetres and degrees for people (fixed decimals, never "-0")."""

from __future__ import annotations

import math

import pytest

from core.units import fmt_deg, fmt_mm, wrap_deg


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
