"""core.study's extensible-arm metrics: tip-IK success over a target grid, repeatability under slip.

Expectations from outside the code under test: a tip position made by forward kinematics of a
posture inside the rack and bending limits is reachable; one farther from the base than every
segment straight at ``rack_max`` is not (a bent segment's chord is shorter than its arc); Hughes
2020 Table I: open loop, two segments spread more than one (+-29 mm against +-19 mm), and
closing the loop on the measured tip takes the slip out.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.kinematics import delta as dk
from core.robots import ExtensibleArm, load
from core.study import StudySpec, ik_targets, reach_of, run_study, tip_ik_metrics

ARM = load("extensible")


def inside_postures(robot: ExtensibleArm, count: int, seed: int) -> np.ndarray:
    """Tip positions of random postures well inside the rack and bending limits."""
    rng = np.random.default_rng(seed)
    n = robot.n_segments
    tips = []
    while len(tips) < count:
        b = robot.bend_max * 0.8 * np.sqrt(rng.uniform(0, 1, n))
        az = rng.uniform(-np.pi, np.pi, n)
        dz = rng.uniform(robot.rack_min - robot.L0, robot.rack_max - robot.L0, n)
        delta = np.stack([b * np.cos(az), b * np.sin(az), dz], axis=-1)
        racks = dk.actuators_from_delta(delta, robot.phi, robot.L0)
        if np.all(racks > robot.rack_min + 0.005) and np.all(racks < robot.rack_max - 0.005):
            tips.append(dk.tip_position(robot, delta))
    return np.array(tips)


def test_targets_inside_the_limits_succeed_and_beyond_the_reach_fail() -> None:
    assert isinstance(ARM, ExtensibleArm)
    reach = reach_of(ARM)
    assert reach == pytest.approx(2 * 0.41)
    inside = inside_postures(ARM, 3, seed=4)
    outside = np.array([[0.0, 0.0, reach + 0.03], [reach * 0.75, reach * 0.75, 0.05]])
    assert np.all(np.linalg.norm(outside, axis=1) > reach)
    got = tip_ik_metrics(ARM, np.vstack([inside, outside]))
    assert got == {"tip_ik_success": 3 / 5, "tip_ik_targets": 5.0}


def test_the_target_grid_is_the_box_cell_centres() -> None:
    t = ik_targets(0.6, 3)
    assert t.shape == (27, 3)
    assert sorted(set(t[:, 0].round(9))) == pytest.approx([-0.4, 0.0, 0.4])
    assert sorted(set(t[:, 2].round(9))) == pytest.approx([0.1, 0.3, 0.5])


def test_every_variant_is_scored_on_the_same_grid_and_longer_racks_reach_more(tmp_path: Path) -> None:
    spec = StudySpec(objects=0, ik_grid=3, slip_points=0)
    rows = run_study("extensible", {"segments.rack_max": [0.3, 0.41]}, tmp_path / "s", spec)
    assert all(r["error"] == "" for r in rows)
    assert [r["tip_ik_box_m"] for r in rows] == [pytest.approx(0.82)] * 2
    assert [r["tip_ik_targets"] for r in rows] == [27.0, 27.0]
    # Grid points straight above the base: (0, 0, 0.41) is within both arms' reach (straight
    # segments of 0.205 m); (0, 0, 0.683) is beyond the short arm's 2 x 0.3 m, within 2 x 0.41 m.
    assert 0 < rows[0]["tip_ik_success"] < rows[1]["tip_ik_success"] < 1


def test_slip_two_segments_spread_more_than_one_and_the_tip_loop_corrects(tmp_path: Path) -> None:
    spec = StudySpec(objects=0, ik_grid=0, slip_points=2, slip_repeats=3)
    rows = run_study("extensible", {"segments.count": [1, 2]}, tmp_path / "s", spec)
    one, two = rows
    assert one["error"] == two["error"] == ""
    assert two["slip_open_spread_m"] > one["slip_open_spread_m"] > 0
    for r in rows:
        assert r["slip_tip_error_m"] < 0.003 < r["slip_open_error_m"]
        assert r["slip_tip_spread_m"] < r["slip_open_spread_m"]
