"""The Repeatability panel's closed-loop toggle and serve.py's --slip (issue #17.4)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from console.panels.repeatability import RepeatabilityPanel, run_repeatability
from console.panels.repeatability_view import RepeatabilityResult, result_html
from core.robots import load
from fakes import console_app

EXT = load("extensible")
REPO = Path(__file__).resolve().parents[2]


class FakeRunner:
    started = False
    period_s = 0.01

    def stop(self) -> None:
        pass


class FakeTip:
    def measure(self) -> np.ndarray:
        return np.zeros(3)


def test_closed_loop_toggle_is_disabled_without_a_tip_sensor(server) -> None:
    app = console_app(EXT, server, panels=(), extensible_runner=FakeRunner())
    panel = app.add_panel(RepeatabilityPanel)
    assert panel is not None and panel.closed.disabled and panel.closed.value is False
    assert "--slip" in panel.closed.hint


def test_closed_loop_toggle_is_offered_with_a_tip_sensor(server) -> None:
    app = console_app(EXT, server, panels=(), extensible_runner=FakeRunner(),
                      tip_sensor=FakeTip())
    panel = app.add_panel(RepeatabilityPanel)
    assert panel is not None and not panel.closed.disabled


def test_closed_loop_without_a_tip_sensor_is_refused_and_moves_nothing() -> None:
    with pytest.raises(ValueError, match="tip sensor"):
        run_repeatability(FakeRunner(), EXT, [0.0, 0.0, 0.3], 1, closed_loop=True)  # type: ignore[arg-type]


def test_result_names_what_measured_the_tip() -> None:
    tips = np.zeros((2, 3))
    enc = result_html(RepeatabilityResult(np.zeros(3), tips, 2))
    assert "tip from the encoders;" in enc and "±19 mm" in enc
    closed = result_html(RepeatabilityResult(np.zeros(3), tips, 2, source="tip sensor",
                                             closed_loop=True))
    assert "tip from the tip sensor (closed loop on it)" in closed


@pytest.mark.parametrize("args", [("--robot", "soft-arm", "--slip", "0.1"),
                                  ("--robot", "extensible", "--hardware", "mock", "--slip", "0.1"),
                                  ("--robot", "extensible", "--slip", "0.9")])
def test_serve_refuses_slip_off_the_extensible_emulator(args: tuple[str, ...]) -> None:
    result = subprocess.run([sys.executable, str(REPO / "serve.py"), *args], cwd=REPO,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and "--slip" in result.stderr
