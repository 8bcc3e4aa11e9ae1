"""Browser test of issue #19.5 on the default extensible console, kept to what needs a page: the
hold-to-jog buttons pressed with a real mouse, and the text the page draws.

serve.py runs in a subprocess (conftest's ``console_server``, the in-process mock device). From
the start pose (``console.core.model.ExtensibleModel.initial``: straight, racks at mid-range) a
held bend jog moves the tip; after a clamp (Retract, then bend: every rack at rack_min) the page
shows the clamp note, and no text on the page reads "-0". The header's Phase field says idle.
The typed target and Preview of this flow, and the same jogs sent as a browser sends them, run
headlessly in tests/console/test_extensible_start_flow.py. Screenshots go to ``artifacts/``.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from browser_tabs import open_console, wait_until
from lab_rig import jog_button

from console.core.model import ExtensibleModel
from core.kinematics import delta as dk
from core.robots import load

# alone: hold-to-run buttons (a 300 ms hold expiry; conftest's SUITE_PART=alone)
pytestmark = [pytest.mark.browser, pytest.mark.alone]
ROBOT = load("extensible")
NEGATIVE_ZERO = re.compile(r"(?<![\d.])[-−]0(?:\.0+)?(?![\d.])")


def readout_tip(page) -> np.ndarray:
    return np.array([float(page.locator(f'[data-testid="tip-{k}"]').inner_text())
                     for k in range(3)])


def hold(page, label: str, sign: str, seconds: float) -> None:
    """Press and hold the hold-to-run button ``sign`` beside the Jog slider ``label``."""
    button = jog_button(page, label, sign)
    button.scroll_into_view_if_needed()
    button.hover()
    page.mouse.down()
    time.sleep(seconds)
    page.mouse.up()


def test_held_jog_buttons_move_the_tip_or_clamp_with_a_note_on_the_page(
        page, console_server: Callable[..., str], artifacts_dir: Path) -> None:
    open_console(page, console_server("extensible"), "Tip target", '[data-testid="tip-readout"]')
    start = dk.tip_position(ROBOT, ExtensibleModel(ROBOT).initial()) * 1e3  # mid-range, straight
    wait_until("the readout at the start pose", lambda: np.abs(readout_tip(page) - start).max()
               <= 0.5, 20, show=lambda: str(readout_tip(page)))
    header = page.locator('[data-testid="console-header"]')
    wait_until("the header's phase", lambda: "Phase: idle" in header.inner_text(), 10,
               show=header.inner_text)
    page.screenshot(path=str(artifacts_dir / "browser_extensible_start.png"))

    # A bend jog moves at start (retracted, every rack at rack_min, it was refused).
    hold(page, "Δx₁", "+", 1.0)
    wait_until("the tip moved by the bend jog",
               lambda: np.linalg.norm(readout_tip(page) - start) > 2.0, 5,
               show=lambda: f"{readout_tip(page)} {page.locator('body').inner_text()[-300:]}")

    seen = [readout_tip(page)]

    def still() -> bool:  # the jog ended (its release reached the console)
        time.sleep(0.5)
        seen.append(readout_tip(page))
        return bool(np.abs(seen[-1] - seen[-2]).max() < 0.05)
    wait_until("the jog to end", still, 10)

    # A clamp: retracted, every rack at rack_min, a bend is refused with a note, never "-0".
    page.get_by_role("button", name="Retract (Δ = 0)").click()
    retracted = np.array([0.0, 0.0, ROBOT.n_segments * ROBOT.L0 * 1e3])
    wait_until("the arm retracted", lambda: np.abs(readout_tip(page) - retracted).max() <= 0.5,
               20, show=lambda: str(readout_tip(page)))
    note = page.get_by_text("clamped to +0 mm")
    for _ in range(3):  # a loaded box can lose the lease for a moment ("Not allowed"): again
        hold(page, "Δx₁", "−", 0.5)
        try:
            wait_until("the clamp note", lambda: note.count() > 0, 5)
            break
        except AssertionError:
            continue
    text = page.locator("body").inner_text()
    assert "clamped to +0 mm" in text and "extend δL₁ first" in text, text[-600:]
    assert not NEGATIVE_ZERO.findall(text), [ln for ln in text.splitlines()
                                             if NEGATIVE_ZERO.search(ln)]
    page.screenshot(path=str(artifacts_dir / "browser_extensible_clamp.png"))
