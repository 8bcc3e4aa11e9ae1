"""The CLIs' tables in units people read (issue 18): mm and degrees, the unit in every header;
the numbers are the SI results scaled (JSON and CSV stay SI, tests/core/test_results_csv.py)."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from core.control.capture import FAILURE, INFEASIBLE, SUCCESS, characterise
from core.control.capture.__main__ import format_summary
from core.control.trials import TrialResult
from core.control.trials.__main__ import format_table
from core.planning.grasp import plan_grasp
from core.planning.plan_types import format_plan
from core.robots import load

SOFT = load("soft-arm")


def test_trials_table_shows_the_object_in_mm_and_times_in_s() -> None:
    rows = [TrialResult([-0.16, 0.28, 0.0165], True, None, 31.25, 12.0, "A"),
            TrialResult([-1e-6, 0.2, 0.02], False, "time limit", 150.0, 0.0, "B")]
    lines = format_table(rows).splitlines()
    header = lines[0].split()
    for unit_label in ("(mm)", "(s)"):
        assert unit_label in header
    assert "x (mm)" in lines[0] and "approach (s)" in lines[0] and "return (s)" in lines[0]
    first = lines[1].split()
    assert first[2:5] == ["-160.0", "280.0", "16.5"] and first[6:8] == ["31.2", "12.0"]
    second = lines[2].split()
    assert second[2] == "0.0"  # -1 µm: no "-0.0"
    assert lines[-1] == "total: 1/2 successes"


def test_grasp_plan_table_is_mm_and_degrees() -> None:
    plan = plan_grasp(SOFT, np.zeros(SOFT.n_segments), (-0.2, 0.2), 0.0165)
    text = format_plan(plan)
    lines = text.splitlines()
    assert lines[0].startswith("Object at (-200.0, 200.0) mm, r = 16.5 mm")
    assert f"d1 = {plan.d1 * 1e3:.1f} mm" in lines[1]
    for head in ("r_a (mm)", "phi (deg)", "kappa (1/m)", "palm x (mm)", "th (deg)", "clr (mm)"):
        assert head in lines[2]
    for k, line in enumerate(lines[3:3 + plan.n]):
        cells = line[3:].split()
        assert float(cells[0]) == pytest.approx(plan.radii[k] * 1e3, abs=0.051)
        assert float(cells[1]) == pytest.approx(math.degrees(plan.phis[k]), abs=0.051)
        kappas = [float(v) for v in cells[2:2 + SOFT.n_segments]]
        assert kappas == pytest.approx(plan.kappas[k], abs=0.0051)
        px = float(cells[2 + SOFT.n_segments])
        assert px == pytest.approx(plan.palm_poses[k][0] * 1e3, abs=0.051)
    assert not re.search(r"(^|\s)-0\.0+(\s|$)", text)


def test_capture_summary_rows_and_result_are_mm() -> None:
    cmap = characterise(SOFT, spacing=0.01)
    text = format_summary(cmap, {SUCCESS: "o", FAILURE: "x", INFEASIBLE: " "})
    lines = text.splitlines()
    assert lines[0].startswith("y (mm)") and " cm" not in text
    ys = [float(line[:6]) for line in lines[1:1 + len(cmap.ys)]]
    assert ys == pytest.approx(cmap.ys[::-1] * 1e3, abs=0.5)  # top row first
    d = float(re.search(r"equivalent diameter (\d+) mm", lines[-1]).group(1))
    assert d == pytest.approx(cmap.equivalent_diameter() * 1e3, abs=0.5)
    assert f"object r = {cmap.radius * 1e3:.1f} mm, grid 10 mm" in lines[-1]
