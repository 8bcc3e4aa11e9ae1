"""The extensible arm's Δ jog honours the bending limit theta = |(dx, dy)| / d <= theta_max:
sliders, single-coordinate jogs, whole-configuration clamps, commanded states and held jogs.
Expectations are closed forms (the bending disc of radius d theta_max, the rack formula)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from console.core.hold_to_run import HoldToRun
from console.core.model import ExtensibleModel
from console.core.state import StateStore
from core.robots import load

EXT = load("extensible")
R = EXT.rack_radius * EXT.theta_max  # largest |(dx, dy)|: 47.1 mm for d = 30 mm, theta_max = pi/2


def racks(q: np.ndarray) -> np.ndarray:
    beta = -EXT.phi + 2 * np.pi * np.arange(3) / 3
    return EXT.L0 + q[:, 2:3] - q[:, 0:1] * np.cos(beta) - q[:, 1:2] * np.sin(beta)


def theta(q: np.ndarray) -> np.ndarray:
    return np.hypot(q[:, 0], q[:, 1]) / EXT.rack_radius


def in_limits(q: np.ndarray) -> bool:
    r = racks(q)
    return bool(np.all(r >= EXT.rack_min - 1e-12) and np.all(r <= EXT.rack_max + 1e-12)
                and np.all(theta(q) <= EXT.theta_max))


def test_the_limit_is_ninety_degrees_per_segment() -> None:
    assert EXT.theta_max == pytest.approx(math.pi / 2)
    assert R == pytest.approx(0.03 * math.pi / 2)


def test_bending_sliders_span_the_bending_disc() -> None:
    model = ExtensibleModel(EXT)
    for coord in model.coordinates:
        if coord.index[1] < 2:  # the racks alone would allow 240 mm
            assert (coord.lo, coord.hi) == pytest.approx((-0.047, 0.047))
            assert "θ ≤ 90°" in coord.hint


def test_jog_beyond_the_bending_limit_clamps_to_the_disc_with_a_clear_note() -> None:
    model = ExtensibleModel(EXT)
    q = np.array([[0.0, 0.02, 0.2], [0.01, 0.0, 0.1]])
    out, note = model.set_coordinate(q, model.coordinates[0], 0.08)  # Δx₁
    expected = math.sqrt(R ** 2 - 0.02 ** 2)  # the disc's edge at Δy₁ = 20 mm
    assert out[0, 0] == pytest.approx(expected, rel=1e-9)
    assert theta(out)[0] <= EXT.theta_max and in_limits(out)
    np.testing.assert_array_equal(np.delete(out.ravel(), 0), np.delete(q.ravel(), 0))
    assert note is not None and "Δx₁ clamped" in note and "bending limit θ = 90°" in note
    # The other way too, and a value inside the disc is applied as asked.
    out, note = model.set_coordinate(q, model.coordinates[0], -0.08)
    assert out[0, 0] == pytest.approx(-expected, rel=1e-9) and "bending limit" in note
    out, note = model.set_coordinate(q, model.coordinates[0], 0.03)
    assert out[0, 0] == 0.03 and note is None


def test_when_the_racks_bind_first_the_note_names_the_rack() -> None:
    model = ExtensibleModel(EXT)
    q = np.array([[0.0, 0.0, 0.01], [0.0, 0.0, 0.1]])  # barely extended: racks bind at 20 mm
    out, note = model.set_coordinate(q, model.coordinates[0], 0.04)
    assert out[0, 0] == pytest.approx(0.02, abs=1e-9) and in_limits(out)
    assert note is not None and "rack" in note and "bending" not in note


def test_clamp_scales_an_over_bent_segment_onto_the_disc_keeping_its_direction() -> None:
    model = ExtensibleModel(EXT)
    q = np.array([[0.06, 0.03, 0.25], [0.0, -0.01, 0.1]])  # segment 1: 2.2 rad, racks fine
    assert np.all(racks(q) >= EXT.rack_min) and np.all(racks(q) <= EXT.rack_max)
    out, notes = model.clamp(q)
    assert in_limits(out)
    assert theta(out)[0] == pytest.approx(EXT.theta_max, rel=1e-9)
    np.testing.assert_allclose(out[0, :2] / np.linalg.norm(out[0, :2]),
                               q[0, :2] / np.linalg.norm(q[0, :2]), atol=1e-12)
    np.testing.assert_array_equal(out[1], q[1])
    assert out[0, 2] == q[0, 2]
    assert len(notes) == 1 and "segment 1" in notes[0] and "bending limit θ = 90°" in notes[0]
    again, notes = model.clamp(out)  # clamped once is within the limits: untouched
    np.testing.assert_array_equal(again, out)
    assert notes == ()


def test_commanded_configurations_are_clamped_and_bad_ones_refused() -> None:
    store = StateStore(ExtensibleModel(EXT))
    state = store.request(np.array([[0.09, 0.0, 0.3], [0.0, 0.0, 0.1]]), "jog")
    assert in_limits(np.asarray(state.q)) and any("bending limit" in n for n in state.notes)
    before = store.command
    with pytest.raises(ValueError, match="finite"):
        store.request(np.array([[np.nan, 0.0, 0.3], [0.0, 0.0, 0.1]]), "jog")
    assert store.command is before  # moved nothing


def test_a_held_bending_jog_stops_at_the_limit() -> None:
    clock = {"t": 0.0}
    store = StateStore(ExtensibleModel(EXT), np.array([[0.0, 0.0, 0.2], [0.0, 0.0, 0.1]]))
    hold = HoldToRun(store, allowed=lambda cid: True, clock=lambda: clock["t"], rate_hz=50.0)
    coord = hold.model.coordinates[0]  # Δx₁ +
    peak = 0.0
    for k in range(200):  # 4 s, renewed every 0.1 s: far longer than reaching the limit takes
        if k % 5 == 0:
            hold.hold(1, coord, +1)
        clock["t"] += 0.02
        hold.tick()
        q = np.asarray(store.command.q)
        assert in_limits(q)
        peak = max(peak, float(theta(q)[0]))
    assert peak == pytest.approx(EXT.theta_max, rel=1e-6)
