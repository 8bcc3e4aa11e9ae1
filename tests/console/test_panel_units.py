"""Units people read (issue 18) in the Readout, Capture region and Trials panels: mm and degrees
in every field, the unit in every label; SI still goes to the library underneath."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from console.app import ConsoleApp
from console.core.model import model_for
from console.panels.soft_arm.capture import CapturePanel, summary_markdown
from console.panels.common.readout import extensible_readout_html, soft_arm_readout_html
from console.panels.soft_arm.trials import TrialsPanel, results_markdown
from core.control.capture import characterise
from core.control.trials import TrialResult, paper_locations
from core.kinematics import planar as pk
from core.robots import load

SOFT = load("soft-arm")
EXT = load("extensible")


def test_trials_fields_are_millimetres_and_the_batch_gets_metres(server) -> None:
    app = ConsoleApp(SOFT, server, panels=(TrialsPanel,))
    panel = app.panel(TrialsPanel)
    assert {panel.x.label, panel.y.label, panel.r.label} == {
        "Custom x (mm)", "Custom y (mm)", "Object r (mm)"}
    assert panel.r.value == pytest.approx(SOFT.capture.nominal_object_radius * 1e3)
    r0 = SOFT.capture.nominal_object_radius
    spots = panel.objects()  # the paper's A-E with the default radius
    assert [k for k, _ in spots] == list(paper_locations())
    assert all(o[2] == pytest.approx(r0) for _, o in spots)
    panel.spots.value = "custom"
    panel.x.value, panel.y.value, panel.r.value = -120.0, 250.0, 20.0
    ((label, obj),) = panel.objects()
    assert label == "custom" and obj == pytest.approx((-0.12, 0.25, 0.02))


def test_results_table_names_the_unit_of_every_time() -> None:
    md = results_markdown([TrialResult([-0.1, 0.2, 0.0165], True, None, 10.04, 8.0, "A")])
    header = md.splitlines()[0]
    assert "approach (s)" in header and "return (s)" in header
    assert "| 10.0 | 8.0 |" in md


def test_capture_fields_and_summary_are_millimetres(server) -> None:
    app = ConsoleApp(SOFT, server, panels=(CapturePanel,))
    panel = app.panel(CapturePanel)
    assert (panel.radius.label, panel.spacing.label) == ("Object r (mm)", "Grid (mm)")
    assert panel.radius.value == pytest.approx(SOFT.capture.nominal_object_radius * 1e3)
    assert panel.radius.max == pytest.approx(SOFT.gripper.max_object_radius * 1e3)
    m = characterise(SOFT, spacing=0.01)
    text = summary_markdown(m)
    assert " cm" not in text and "on a 10 mm grid" in text
    d = float(re.search(r"equivalent diameter \*\*(-?\d+) mm\*\*", text).group(1))
    assert d == pytest.approx(m.equivalent_diameter() * 1e3, abs=0.5)
    cx, cy = (float(v) for v in re.search(r"centroid \((-?\d+), (-?\d+)\) mm", text).groups())
    assert (cx, cy) == pytest.approx(tuple(np.asarray(m.centroid()) * 1e3), abs=0.5)
    assert "-0 " not in text and "(-0," not in text


def _cells(html: str) -> dict[str, str]:
    return dict(re.findall(r'data-testid="([\w-]+)"[^>]*>(?:<code>)?(?:<span[^>]*>)?([^<]*)', html))


def test_readout_cells_are_mm_and_degrees_with_fixed_decimals_and_no_minus_zero() -> None:
    model = model_for(SOFT)
    q = np.zeros(SOFT.n_segments)
    q[0] = -1e-7  # a hair off straight: x rounds to zero and must read +0.0, not -0.0
    cells = _cells(soft_arm_readout_html(model, q))
    tip = pk.forward_kinematics(q, SOFT.lengths, SOFT.base_pose)[-1]
    assert cells["tip-0"] == "+0.0"
    assert cells["tip-1"] == f"{tip[1] * 1e3:+.1f}" and cells["tip-2"] == "+90.0"
    html = soft_arm_readout_html(model, q)
    assert "x (mm)" in html and "θ (°)" in html
    ext = extensible_readout_html(model_for(EXT), np.zeros((EXT.n_segments, 3)))
    cells = _cells(ext)
    assert cells["tip-3"] == "0.0"  # tilt (°) of the straight arm
    assert cells["rack-1-1"].startswith(f"{EXT.rack_min * 1e3:.1f}")
    assert "tilt (°)" in ext and "z (mm)" in ext and f"{EXT.rack_max * 1e3:.0f} mm" in ext
    assert not math.isnan(float(cells["tip-2"]))
