"""Closed-loop tip positioning (core.control.closed_loop) against slipping racks."""

from __future__ import annotations

import numpy as np
import pytest

from core.control.closed_loop import ClosedLoopSettings, correction, position
from core.control.rack_slip import SlipModel
from core.control.repeatability import SimulatedArm, reach, sample_targets, with_segments
from core.kinematics import delta as dk
from core.kinematics.delta_ik import solve_tip_ik
from core.robots import load

ARM2 = load("extensible")
STRONG = SlipModel(fraction=0.1, jitter=0.02, tip_noise=0.002, seed=5)


def _tip(arm, lengths):
    return dk.tip_position(arm, dk.delta_from_actuators(lengths, arm.phi, arm.L0))


@pytest.mark.parametrize("n", [1, 2])
def test_tip_loop_ends_within_3_mm_where_the_open_loop_misses_by_15_mm(n: int) -> None:
    arm = with_segments(ARM2, n)
    targets = sample_targets(arm, 6, seed=11)
    errors = {}
    for mode in ("open", "encoders", "tip"):
        sim = SimulatedArm(arm, STRONG)  # same seed: the same slip draws for every mode
        errors[mode] = np.array([np.linalg.norm(reach(sim, t, mode) - t) for t in targets])
    assert errors["open"].mean() > 0.015
    assert errors["tip"].max() < 0.003
    # The encoders cannot see a rack slipping on its pinion: closing the loop on them changes
    # nothing (the same draws give the very same tips).
    np.testing.assert_array_equal(errors["encoders"], errors["open"])


@pytest.mark.parametrize("n", [1, 2])
def test_without_slip_or_noise_both_loops_hit_the_ik_tip(n: int) -> None:
    arm = with_segments(ARM2, n)
    exact = SlipModel(fraction=0.0, jitter=0.0, tip_noise=0.0)
    for t in sample_targets(arm, 3, seed=2):
        for mode in ("open", "tip"):
            assert np.linalg.norm(reach(SimulatedArm(arm, exact), t, mode) - t) < 1e-3


def test_one_correction_moves_the_commanded_tip_by_the_measured_error() -> None:
    target = sample_targets(ARM2, 1, seed=4)[0]
    cmd = solve_tip_ik(ARM2, target).lengths
    e = np.array([0.002, -0.001, 0.0015])
    new = correction(ARM2, target, cmd, target - e, cmd)
    # Gauss-Newton on the tip: J J^+ e = e for a full-rank J, up to second order in |e|.
    assert _tip(ARM2, new) - _tip(ARM2, cmd) == pytest.approx(e, abs=5e-5)
    assert correction(ARM2, target, cmd, target, cmd) == pytest.approx(cmd, abs=1e-12)


def test_a_correction_never_leaves_the_rack_limits_and_holds_racks_at_a_limit() -> None:
    arm = with_segments(ARM2, 1)
    cmd = np.array([[arm.rack_max, arm.rack_max - 0.02, arm.rack_max - 0.02]])  # rack 1 at max
    here = _tip(arm, cmd)
    # Ask for a tip far out along the axis: every rack would lengthen.
    new = correction(arm, here + [0.0, 0.0, 0.05], cmd, here, cmd)
    assert new[0, 0] == pytest.approx(arm.rack_max)
    assert np.all(new <= arm.rack_max) and np.all(new >= arm.rack_min)
    assert np.all(new[0, 1:] > arm.rack_max - 0.02)  # the free racks did move out
    assert np.all(dk.bend_angles(dk.delta_from_actuators(new, arm.phi, arm.L0), arm.d)
                  <= arm.theta_max)


def test_position_stops_at_tolerance_and_reports_every_measurement() -> None:
    arm = with_segments(ARM2, 2)
    sim = SimulatedArm(arm, STRONG)
    target = sample_targets(arm, 1, seed=3)[0]
    sim.retract()
    res = position(arm, target, sim.move, sim.tip_measured,
                   settings=ClosedLoopSettings(iterations=8, tolerance=0.001))
    assert len(res.measured) == res.corrections + 1 >= 2
    assert np.linalg.norm(res.measured[0] - target) > 0.005  # the open-loop move missed
    assert np.linalg.norm(res.measured[-1] - target) <= 0.001 or res.corrections == 8


def test_unreachable_target_moves_nothing() -> None:
    arm = with_segments(ARM2, 1)
    moves = []
    with pytest.raises(ValueError, match="out of reach"):
        position(arm, [0.0, 0.0, 2.0], moves.append, lambda: np.zeros(3))
    assert moves == []


def test_bad_settings_are_refused() -> None:
    with pytest.raises(ValueError):
        ClosedLoopSettings(gain=0.0)
    with pytest.raises(ValueError):
        ClosedLoopSettings(iterations=-1)
