"""The open / closed loop repeatability study and its command line (core.control.repeatability)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from core.control.repeatability import Spread, sample_targets, with_segments
from core.control.repeatability.__main__ import main
from core.kinematics.delta_ik import solve_tip_ik
from core.robots import load

ARM2 = load("extensible")


def test_spread_statistics_by_hand() -> None:
    targets = np.array([[0.0, 0.0, 0.3]])
    tips = np.array([[[0.0, 0.0, 0.31], [0.004, 0.0, 0.29], [0.0, -0.002, 0.3]]])
    s = Spread(targets, tips)
    assert s.errors[0] == pytest.approx([0.01, np.hypot(0.004, 0.01), 0.002])
    assert s.spread[0] == pytest.approx([0.002, 0.001, 0.01])
    assert s.summary()["max_spread"] == pytest.approx(0.01)


@pytest.mark.parametrize("n", [1, 2])
def test_targets_are_seeded_and_reachable_inside_the_limits(n: int) -> None:
    arm = with_segments(ARM2, n)
    a, b = sample_targets(arm, 4, seed=9), sample_targets(arm, 4, seed=9)
    np.testing.assert_array_equal(a, b)
    for t in a:
        ik = solve_tip_ik(arm, t)
        assert ik.reachable
        assert np.all(ik.lengths < arm.rack_max - 0.01)


def test_cli_prints_open_encoder_and_tip_loops_for_each_segment_count(capsys) -> None:
    assert main(["--segments", "1", "2", "--points", "2", "--repeats", "3", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["table_i_spread"] == {"1": 0.019, "2": 0.029}
    rows = {(r["segments"], r["mode"]): r for r in out["rows"]}
    for n in (1, 2):
        open_, enc, tip = rows[n, "open"], rows[n, "encoders"], rows[n, "tip"]
        assert enc["mean_error"] == open_["mean_error"]  # encoders are blind to slip
        assert tip["max_error"] < 0.003 < open_["mean_error"]
        assert tip["mean_spread"] < open_["mean_spread"]
    assert main(["--segments", "1", "--points", "1", "--repeats", "1"]) == 0
    text = capsys.readouterr().out
    assert "Table I" in text and "closed, tip" in text and "(mm)" in text


def test_cli_refuses_bad_arguments() -> None:
    with pytest.raises(SystemExit):
        main(["--slip", "0.9"])
    with pytest.raises(SystemExit):
        main(["--segments", "0"])
