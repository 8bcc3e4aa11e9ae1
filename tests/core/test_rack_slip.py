"""Rack slip model (core.control.rack_slip): open-loop moves miss by the closed-form amount."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from core.control.rack_slip import SlipModel, SlippingRacks
from core.kinematics import delta as dk
from core.robots import load

ARM2 = load("extensible")
ARM1 = dataclasses.replace(ARM2, n_segments=1, n_motors=3)
L0 = ARM2.L0


def _move_to_lengths(racks: SlippingRacks, arm, lengths) -> None:
    """Command rack lengths through the encoders, as the runner does (counts from home)."""
    home = dk.motor_counts_from_lengths(arm, dk.robot_rack_lengths(arm, np.zeros((arm.n_segments, 3))))
    counts = dk.motor_counts_from_lengths(arm, np.asarray(lengths)) - home
    racks.move(counts.reshape(arm.n_segments, 3) / arm.counts_per_metre)


def test_single_segment_extension_falls_short_by_the_slip_fraction() -> None:
    f, T = 0.1, 0.2
    racks = SlippingRacks(ARM1, SlipModel(fraction=f, jitter=0.0, tip_noise=0.0))
    _move_to_lengths(racks, ARM1, np.full((1, 3), L0 + T))
    # Encoders read the whole travel, the racks moved (1 - f) of it: the tip is f T short.
    assert racks.encoder_m == pytest.approx(np.full((1, 3), T), abs=1 / ARM1.counts_per_metre)
    assert racks.tip == pytest.approx([0.0, 0.0, L0 + (1 - f) * T], abs=2e-5)


def test_two_segment_extension_loses_less_on_the_distal_platform() -> None:
    f, T1, T2 = 0.08, 0.25, 0.15  # segment lengths L0 + T1, L0 + T2 (straight)
    racks = SlippingRacks(ARM2, SlipModel(fraction=f, jitter=0.0, tip_noise=0.0))
    lengths = np.array([[L0 + T1] * 3, [L0 + T2] * 3])
    _move_to_lengths(racks, ARM2, lengths)
    # Motor 2 (platform 2, load 1/2) drives segment 2's racks by T2 from home; motor 1 (load 1)
    # moves by (L1 - L2) - (home1 - home2) = T1 - T2. Segment 1's racks are m1 + m2.
    m2 = (1 - f / 2) * T2
    m1 = (1 - f) * (T1 - T2)
    seg2 = L0 + m2
    seg1 = L0 + m1 + m2
    assert racks.tip == pytest.approx([0.0, 0.0, seg1 + seg2], abs=3e-5)
    assert np.linalg.norm(racks.tip - [0, 0, 2 * L0 + T1 + T2]) == pytest.approx(
        f * (T1 - T2) + 2 * (f / 2) * T2, abs=3e-5)


def test_bent_single_segment_misses_as_the_shortened_racks_predict() -> None:
    f = 0.12
    racks = SlippingRacks(ARM1, SlipModel(fraction=f, jitter=0.0, tip_noise=0.0))
    cmd = np.array([[0.30, 0.18, 0.22]])
    _move_to_lengths(racks, ARM1, cmd)
    true = L0 + (1 - f) * (cmd - L0)  # every rack short by f of its travel
    expect = dk.tip_position(ARM1, dk.delta_from_actuators(true, ARM1.phi, ARM1.L0))
    commanded = dk.tip_position(ARM1, dk.delta_from_actuators(cmd, ARM1.phi, ARM1.L0))
    assert racks.tip == pytest.approx(expect, abs=3e-5)
    assert np.linalg.norm(racks.tip - commanded) > 0.015  # the open loop misses by > 15 mm


def test_per_move_draws_have_the_models_mean_and_spread_and_are_seeded() -> None:
    model = SlipModel(fraction=0.08, jitter=0.02, tip_noise=0.0, seed=7)

    def fractions(seed_model: SlipModel) -> np.ndarray:
        racks = SlippingRacks(ARM1, seed_model)
        out = []
        for _ in range(300):
            _move_to_lengths(racks, ARM1, np.full((1, 3), 0.25))
            out.append((racks.actual_m / racks.encoder_m).ravel())
            _move_to_lengths(racks, ARM1, np.full((1, 3), L0))  # retract: re-homed
            assert racks.actual_m == pytest.approx(np.zeros((1, 3)))
        return 1 - np.array(out)

    s = fractions(model)
    assert s.mean() == pytest.approx(0.08, abs=0.004)
    assert s.std() == pytest.approx(0.02, rel=0.15)
    assert np.array_equal(s, fractions(model))  # same seed, same draws


def test_a_motor_that_reverses_after_a_short_rest_draws_a_new_slip() -> None:
    """The runner queues the next move as soon as one settles (a retract, then the move out):
    the motors rest for less than rest_s, but every move out must still get its own draw, or
    the open loop would repeat one slip forever (issue #17.4's live comparison)."""
    model = SlipModel(fraction=0.08, jitter=0.02, tip_noise=0.0, seed=3)
    racks = SlippingRacks(ARM1, model)
    out_m, dt, fractions = 0.15, 0.01, []
    for _ in range(60):
        for goal in (out_m, 0.0):  # out, then back to the retracted pose, tick by tick
            start = racks.encoder_m.copy()
            for k in range(1, 31):
                racks.step(start + (goal - start) * k / 30, dt)
            racks.step(np.full((1, 3), goal), dt)  # one tick at rest (< rest_s)
            if goal:
                fractions.append(1 - (racks.actual_m / racks.encoder_m).ravel())
    s = np.array(fractions)  # (moves, motors)
    assert s.std(axis=0) == pytest.approx([0.02] * 3, rel=0.3)  # every move a new draw
    assert s.mean() == pytest.approx(0.08, abs=0.01)
    # In one direction without a rest the move goes on: no new draw on the way.
    racks = SlippingRacks(ARM1, model)
    racks.step(np.full((1, 3), 0.05), dt)
    first = racks.slip.copy()
    racks.step(np.full((1, 3), 0.05), dt)  # one still tick
    racks.step(np.full((1, 3), 0.10), dt)
    assert np.array_equal(racks.slip, first)


def test_a_correction_move_slips_only_on_its_own_travel() -> None:
    f = 0.1
    racks = SlippingRacks(ARM1, SlipModel(fraction=f, jitter=0.0, tip_noise=0.0))
    _move_to_lengths(racks, ARM1, np.full((1, 3), L0 + 0.2))
    _move_to_lengths(racks, ARM1, np.full((1, 3), L0 + 0.22))
    assert racks.tip[2] == pytest.approx(L0 + 0.9 * 0.2 + 0.9 * 0.02, abs=3e-5)


def test_the_encoders_never_see_the_slip_and_a_zero_fraction_is_exact() -> None:
    racks = SlippingRacks(ARM2, SlipModel(fraction=0.0, jitter=0.0, tip_noise=0.0))
    cmd = np.array([[0.30, 0.20, 0.25], [0.15, 0.12, 0.1]])
    _move_to_lengths(racks, ARM2, cmd)
    expect = dk.tip_position(ARM2, dk.delta_from_actuators(cmd, ARM2.phi, ARM2.L0))
    assert racks.tip == pytest.approx(expect, abs=5e-5)


def test_tip_measurement_noise_has_the_models_sigma() -> None:
    racks = SlippingRacks(ARM1, SlipModel(fraction=0.0, jitter=0.0, tip_noise=0.002, seed=1))
    samples = np.array([racks.measured_tip() for _ in range(2000)]) - racks.tip
    assert samples.std(axis=0) == pytest.approx([0.002] * 3, rel=0.1)
    averaged = np.array([racks.measured_tip(16) for _ in range(500)]) - racks.tip
    assert averaged.std(axis=0) == pytest.approx([0.0005] * 3, rel=0.15)


@pytest.mark.parametrize("kw", [{"fraction": 0.6}, {"jitter": -0.1}, {"tip_noise": math.nan}])
def test_bad_slip_parameters_are_refused(kw: dict) -> None:
    with pytest.raises(ValueError, match="slip"):
        SlipModel(**kw)
