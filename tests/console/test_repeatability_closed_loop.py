"""The Repeatability panel without and with a tip sensor, and serve.py's --slip (issue #17.4)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from console.panels.extensible.repeatability import RepeatabilityPanel, run_repeatability
from console.panels.extensible.repeatability_view import Comparison, RepeatabilityResult, comparison_html
from core.robots import load
from fakes import console_app

EXT = load("extensible")
REPO = Path(__file__).resolve().parents[2]


class FakeRunner:
    started = False
    period_s = 0.01
    failure = None
    view = None

    def stop(self) -> None:
        pass


class FakeTip:
    def measure(self) -> np.ndarray:
        return np.zeros(3)


def test_without_a_tip_sensor_the_panel_says_there_is_nothing_to_compare(server) -> None:
    app = console_app(EXT, server, panels=(), extensible_runner=FakeRunner())
    panel = app.add_panel(RepeatabilityPanel)
    assert panel is not None and panel.run_btn.label == "Run open loop (encoders)"
    assert "--slip" in panel.run_btn.hint
    assert 'data-state="no-slip"' in panel.note.content and "--slip" in panel.note.content
    assert "nothing to beat" in panel.note.content


def test_with_a_tip_sensor_the_panel_offers_the_comparison(server) -> None:
    app = console_app(EXT, server, panels=(), extensible_runner=FakeRunner(),
                      tip_sensor=FakeTip())
    panel = app.add_panel(RepeatabilityPanel)
    assert panel is not None and panel.run_btn.label == "Run open vs closed loop"
    assert 'data-state="slip"' in panel.note.content


def test_closed_loop_without_a_tip_sensor_is_refused_and_moves_nothing() -> None:
    with pytest.raises(ValueError, match="tip sensor"):
        run_repeatability(FakeRunner(), EXT, [0.0, 0.0, 0.3], 1, closed_loop=True)  # type: ignore[arg-type]


def test_result_names_what_measured_the_tip() -> None:
    tips = np.zeros((2, 3))
    enc = comparison_html(Comparison(np.zeros(3), 2, 2, False,
                                     open=RepeatabilityResult(np.zeros(3), tips, 2)))
    assert "tips measured by the encoders" in enc and "±19" in enc and "±29" in enc
    assert "needs the tip sensor" in enc  # no closed loop row without one
    closed = comparison_html(Comparison(
        np.zeros(3), 2, 2, True, open=RepeatabilityResult(np.zeros(3), tips, 2, source="tip sensor"),
        closed=RepeatabilityResult(np.zeros(3), tips, 2, source="tip sensor", closed_loop=True)))
    assert "tips measured by the tip sensor" in closed and "closed loop on the tip" in closed


@pytest.mark.parametrize("args", [("--robot", "soft-arm", "--slip", "0.1"),
                                  ("--robot", "extensible", "--hardware", "mock", "--slip", "0.1"),
                                  ("--robot", "extensible", "--slip", "0.9")])
def test_serve_refuses_slip_off_the_extensible_emulator(args: tuple[str, ...]) -> None:
    result = subprocess.run([sys.executable, str(REPO / "serve.py"), *args], cwd=REPO,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and "--slip" in result.stderr
