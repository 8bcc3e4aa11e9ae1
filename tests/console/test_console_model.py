"""Console limits: jogged configurations stay feasible, clamps are the largest feasible move."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from console.core.model import ExtensibleModel, SoftArmModel, model_for
from console.core.state import StateStore
from core.kinematics import delta as dk
from core.robots import load

EXT = load("extensible")
SOFT = load("soft-arm")


def racks(q: np.ndarray) -> np.ndarray:
    """Closed-form rack lengths L0 + dL - dx cos(beta_j) - dy sin(beta_j), (n, 3)."""
    beta = -EXT.phi + 2 * np.pi * np.arange(3) / 3
    return EXT.L0 + q[:, 2:3] - q[:, 0:1] * np.cos(beta) - q[:, 1:2] * np.sin(beta)


def feasible(q: np.ndarray, tol: float = 1e-9) -> bool:
    """Racks within their limits and every bend |(dx, dy)| / d within theta_max."""
    r = racks(q)
    bend = np.hypot(q[:, 0], q[:, 1]) - EXT.rack_radius * EXT.theta_max
    return bool(np.all(r >= EXT.rack_min - tol) and np.all(r <= EXT.rack_max + tol)
                and np.all(bend <= tol))


def within_bend_limit(q: np.ndarray) -> np.ndarray:
    """q with each segment's (dx, dy) scaled into the bending disc (racks stay feasible: the
    scaling moves them towards their in-range mean)."""
    size = np.hypot(q[:, 0], q[:, 1])
    limit = EXT.rack_radius * EXT.theta_max * (1 - 1e-9)
    q[:, :2] *= np.minimum(1.0, limit / np.maximum(size, 1e-300))[:, None]
    return q


rack_lengths = st.floats(EXT.rack_min, EXT.rack_max)
feasible_q = st.lists(rack_lengths, min_size=6, max_size=6).map(
    lambda ls: within_bend_limit(dk.delta_from_actuators(np.reshape(ls, (2, 3)), EXT.phi, EXT.L0)))


@settings(max_examples=200, deadline=None)
@given(q=feasible_q, which=st.integers(0, 5), value=st.floats(-0.5, 0.5))
def test_jogging_one_coordinate_keeps_racks_feasible_and_clamps_maximally(q, which, value):
    model = ExtensibleModel(EXT)
    coord = model.coordinates[which]
    out, note = model.set_coordinate(q, coord, value)
    assert feasible(out)
    others = np.ones(q.shape, bool)
    others[coord.index] = False
    np.testing.assert_allclose(out[others], q[others], atol=1e-12)
    applied = out[coord.index]
    if note is None:
        assert applied == pytest.approx(value, abs=1e-9)
    else:
        assert "clamped" in note
        # Largest feasible move: one micrometre further towards the request is infeasible.
        beyond = out.copy()
        beyond[coord.index] += 1e-6 * np.sign(value - applied)
        assert not feasible(beyond, tol=0.0)


@settings(max_examples=200, deadline=None)
@given(q=st.lists(st.floats(-0.6, 0.6), min_size=6, max_size=6).map(
    lambda v: np.reshape(v, (2, 3))))
def test_clamp_returns_feasible_configurations_and_keeps_feasible_ones(q):
    model = ExtensibleModel(EXT)
    out, notes = model.clamp(q)
    assert feasible(out)
    if feasible(q, tol=-1e-9):  # strictly inside the limits: untouched
        np.testing.assert_array_equal(out, q)
        assert notes == ()
    elif not np.array_equal(out, q):
        assert notes
    # Bending keeps its direction (only scaled) within each segment.
    for i in range(2):
        cross = out[i, 0] * q[i, 1] - out[i, 1] * q[i, 0]
        assert cross == pytest.approx(0.0, abs=1e-12)
        assert out[i, :2] @ q[i, :2] >= 0.0


def test_bending_slider_range_is_exactly_what_some_extension_allows():
    model = ExtensibleModel(EXT)
    dl = np.linspace(0.0, EXT.rack_max - EXT.L0, 3601)
    for coord in model.coordinates:
        seg, axis = coord.index
        if axis == 2:
            assert (coord.lo, coord.hi) == pytest.approx((0.0, EXT.rack_max - EXT.L0))
            continue
        for value, reachable in ((coord.hi, True), (coord.hi + coord.step, False)):
            qs = np.zeros((len(dl), 2, 3))
            qs[:, seg, 2] = dl
            qs[:, seg, axis] = value
            assert any(feasible(q) for q in qs) is reachable
        assert coord.lo == -coord.hi


def test_bending_a_retracted_segment_says_to_extend_first():
    model = ExtensibleModel(EXT)
    out, note = model.set_coordinate(model.zero(), model.coordinates[0], 0.05)
    np.testing.assert_array_equal(out, model.zero())
    assert note is not None and "extend δL₁ first" in note
    assert "-0" not in note  # the clamp to 0 mm reads "+0 mm", never "-0 mm"
    out, note = model.set_coordinate(model.zero(), model.coordinates[0], -0.05)
    assert note is not None and "clamped to +0 mm" in note and "-0" not in note


def test_the_extensible_arm_starts_straight_at_mid_range_with_room_to_bend_both_ways():
    """Issue #19.5: retracted, every rack sits at rack_min and every bend is refused. The
    console's first command is the straight arm with every rack at mid-range (the store's
    default), so every bending coordinate can move both ways by a full slider step."""
    model = ExtensibleModel(EXT)
    q0 = StateStore(model).command.q
    np.testing.assert_array_equal(q0, model.initial())
    mid = (EXT.rack_min + EXT.rack_max) / 2
    np.testing.assert_allclose(racks(np.asarray(q0)), mid, atol=1e-3)  # whole millimetres
    assert feasible(np.asarray(q0)) and not np.any(q0[:, :2])
    for coord in model.coordinates:
        for step in (-coord.step, coord.step):
            out, note = model.set_coordinate(np.asarray(q0), coord, q0[coord.index] + step)
            assert note is None and out[coord.index] == pytest.approx(q0[coord.index] + step)
    # The soft arm still starts straight.
    np.testing.assert_array_equal(StateStore(model_for(SOFT)).command.q, np.zeros(6))


def test_planar_curvature_is_clipped_to_kappa_max_with_a_note():
    model = SoftArmModel(SOFT)
    out, note = model.set_coordinate(model.zero(), model.coordinates[2], 40.0)
    assert out[2] == SOFT.kappa_max and np.count_nonzero(out) == 1
    assert note is not None and "κ₃" in note
    out, note = model.set_coordinate(model.zero(), model.coordinates[2], -3.0)
    assert out[2] == -3.0 and note is None


@pytest.mark.parametrize("robot, bad, message", [
    (SOFT, np.zeros(5), r"shape \(6,\)"),
    (SOFT, [0, 0, np.nan, 0, 0, 0], "finite"),
    (EXT, np.zeros(6), r"shape \(2, 3\)"),
    (EXT, [["a", 0, 0], [0, 0, 0]], "numeric"),
])
def test_bad_configurations_are_refused_with_a_clear_message(robot, bad, message):
    with pytest.raises(ValueError, match=message):
        model_for(robot).validate(bad)


def test_straightening_keeps_extension_and_removes_bending():
    model = ExtensibleModel(EXT)
    q = np.array([[0.02, -0.01, 0.1], [0.0, 0.03, 0.2]])
    np.testing.assert_array_equal(model.straightened(q), [[0, 0, 0.1], [0, 0, 0.2]])
    np.testing.assert_array_equal(SoftArmModel(SOFT).straightened(np.ones(6)), np.zeros(6))
