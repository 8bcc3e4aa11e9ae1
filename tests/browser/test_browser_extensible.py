"""Browser tests of the extensible arm's console: typed tip target -> IK -> arm, and a path run.

serve.py runs in a subprocess (conftest's ``console_server``). Chromium types a target; the readout must show a tip
within 1 mm of it, which the test checks against its own IK (``solve_tip_ik`` /
``tip_position``), the Δ jog boxes must hold a posture whose tip is there too, and an
unreachable target must be reported with the distance the readout shows. The path test previews
and executes a linear traverse on the in-process MockHardware and checks the tip ends at the
path's end (``build_path``). The emulator test runs serve.py with its default hardware (the
device emulator on a pty, through the real serial stack), where the arm view and the readout
show what the encoders measure: a typed target must be reached by the measured tip, over time
(no faster than the tip speed limit allows), after the operator connected and armed it in the
Hardware panel. Screenshots go to ``artifacts/``.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
import pytest
from browser_tabs import open_console, open_tab, wait_until
from robot_files import robot_copy

from console.core.model import ExtensibleModel
from core.kinematics import delta as dk
from core.kinematics.delta_ik import solve_tip_ik
from core.planning.paths import build_path
from core.robots import load

pytestmark = pytest.mark.browser
REPO = Path(__file__).resolve().parents[2]
ROBOT = load("extensible")
READOUT_MM = 0.051  # the readout shows 0.1 mm
@pytest.fixture(scope="module")
def extensible_page(module_page: Any, module_console_server: Callable[..., str]) -> Any:
    """serve.py for the extensible (it composes every panel of that robot), on the mock device,
    loaded once for the typed-target and the path tests (a load costs seconds of software
    rendering; each test types its own start)."""
    open_extensible(module_page, module_console_server("extensible"))
    return module_page


def open_extensible(page, url: str) -> None:
    """Load an extensible console: the Tip target panel and the tip readout there."""
    open_console(page, url, "Tip target", '[data-testid="tip-readout"]')


def field(page, label: str):
    uid = page.locator("label", has_text=label).first.get_attribute("for")
    assert uid, f"no input labelled {label!r}"
    return page.locator(f'[id="{uid}"]')


def type_target(page, xyz_mm) -> None:
    """Type x, y, z as a person would, checking each field shows what was typed: the first fill
    of a number input just mounted again (the Operate tab reopened) can be swallowed by the
    page, which then keeps the old value (seen after a visit to the Hardware tab)."""
    for axis, value in zip("xyz", xyz_mm):
        box = field(page, f"Target {axis} (mm)")
        for _ in range(3):
            box.fill(f"{value:g}")
            if box.input_value() == f"{value:g}":
                break
        box.press("Tab")


def readout_tip(page) -> np.ndarray:
    return np.array([float(page.locator(f'[data-testid="tip-{k}"]').inner_text())
                     for k in range(3)])


def jog_posture(page) -> np.ndarray:
    """The Δ jog sliders' values (m; the sliders show mm) as (n, 3), full precision."""
    labels = [f"{c}{s} (mm)" for s in "₁₂" for c in ("Δx", "Δy", "δL")]
    values = []
    for label in labels:
        uid = page.locator("label", has_text=label).first.get_attribute("for")
        thumb = page.locator(f'[id="{uid}"]').get_by_role("slider")
        values.append(float(thumb.get_attribute("aria-valuenow")))
    return np.array(values).reshape(ROBOT.n_segments, 3) / 1e3


def test_typed_target_moves_the_tip_and_the_jog_sliders(
        extensible_page: Any, artifacts_dir: Path) -> None:
    page = extensible_page
    target = np.array([120.0, -60.0, 350.0])  # mm
    ik = solve_tip_ik(ROBOT, target / 1e3)
    assert ik.reachable and np.linalg.norm(dk.tip_position(ROBOT, ik.delta) - target / 1e3) < 1e-3
    type_target(page, target)
    status = page.locator('[data-testid="target-status"]')
    # A wait for the motion (at the shipped tip speed), not a timing claim: generous, as two
    # browser tests share the 2 cores.
    wait_until("the tip readout at the target",
               lambda: np.abs(readout_tip(page) - target).max() <= 1.0, timeout=30,
               show=lambda: f"readout {readout_tip(page)}; {status.inner_text()!r}")
    wait_until("the reachable status", lambda: status.get_attribute("data-state") == "reachable")
    # The jog sliders mirror the posture the IK chose (the panel rounds them to 1e-6 mm).
    wait_until("the jog sliders in sync", lambda: np.linalg.norm(
        dk.tip_position(ROBOT, jog_posture(page)) * 1e3 - target) <= 1.0)
    time.sleep(0.3)
    page.screenshot(path=str(artifacts_dir / "browser_extensible_target.png"))

    far = np.array([900.0, -60.0, 350.0])  # beyond the 820 mm arm
    assert not solve_tip_ik(ROBOT, far / 1e3).reachable
    type_target(page, far)
    wait_until("the unreachable status",
               lambda: status.get_attribute("data-state") == "unreachable", timeout=15)
    said = float(status.get_attribute("data-error-mm"))
    wait_until("the readout at the closest feasible tip", lambda: abs(
        np.linalg.norm(readout_tip(page) - far) - said) <= 0.2)
    assert said > 1.0 and f"{said:.1f} mm" in status.inner_text()
    racks = [float(t.replace("⚠", "")) for t in
             page.locator('[data-testid^="rack-"][data-near-limit]').all_inner_texts()]
    assert min(racks) >= ROBOT.rack_min * 1e3 - 0.05 and max(racks) <= ROBOT.rack_max * 1e3 + 0.05
    time.sleep(0.3)
    page.screenshot(path=str(artifacts_dir / "browser_extensible_unreachable.png"))


def test_path_preview_and_execute_on_mock_hardware(
        extensible_page: Any, artifacts_dir: Path) -> None:
    page = extensible_page
    # Connecting never arms (issue #27): the operator arms the in-process mock (mock://) in the
    # Hardware panel first; Execute on a disarmed arm would say "arm first".
    open_tab(page, "Hardware")
    page.get_by_role("button", name="Arm device", exact=True).click()
    wait_until("the link armed", lambda: "ARMED" in link_text(page), 20,
               show=lambda: link_text(page))
    open_tab(page, "Operate")
    # Arm holds where the encoders are (the mock starts at the start pose) and makes that the
    # console's command, which the target rides on: type only once it has (else that echo can
    # land between two typed fields, as it would for a person typing within milliseconds).
    armed_at = dk.tip_position(ROBOT, ExtensibleModel(ROBOT).initial()) * 1e3
    wait_until("the command at the armed posture",
               lambda: np.abs(readout_tip(page) - armed_at).max() <= 1.0,
               show=lambda: f"readout {readout_tip(page)}")
    wait_until("the target fields at the armed posture", lambda: np.abs(
        np.array([float(field(page, f"Target {a} (mm)").input_value() or "nan") for a in "xyz"])
        - armed_at).max() <= 1.0)
    start = np.array([100.0, 0.0, 300.0])
    type_target(page, start)
    target_status = page.locator('[data-testid="target-status"]')
    wait_until("the tip at the start", lambda: np.abs(readout_tip(page) - start).max() <= 1.0,
               show=lambda: f"readout {readout_tip(page)}; {target_status.inner_text()!r}")
    status = page.locator('[data-testid="path-status"]')
    page.get_by_role("button", name="Preview").click()
    wait_until("the preview", lambda: status.get_attribute("data-state") == "previewed", 60,
               show=status.inner_text)
    centre = readout_tip(page) / 1e3
    end = build_path("linear", centre, 0.08, "xy")[-1] * 1e3  # default: linear, 80 mm, xy
    page.get_by_text("Paths", exact=True).scroll_into_view_if_needed()
    page.screenshot(path=str(artifacts_dir / "browser_extensible_path_preview.png"))
    page.get_by_role("button", name="Execute").click()
    wait_until("the run to finish", lambda: status.get_attribute("data-state") == "done", 60,
               show=status.inner_text)
    wait_until("the readout at the path's end",
               lambda: np.abs(readout_tip(page) - end).max() <= 1.0)
    wait_until("the jog sliders at the path's end", lambda: np.linalg.norm(
        dk.tip_position(ROBOT, jog_posture(page)) * 1e3 - end) <= 1.0)
    time.sleep(0.3)
    page.screenshot(path=str(artifacts_dir / "browser_extensible_path_done.png"))


@pytest.fixture
def emulator_console(tmp_path: Path, console_server: Any) -> Iterator[str]:
    """``serve.py --robot <extensible>`` with its default hardware (no ``--hardware``): the
    device emulator on a pty. The robot file is the shipped one with 0.5 s link timeout and
    watchdog (like tests/hw_bridge/test_extensible_runner.py): the loop shares its process with the GUI
    and this 2-core box with other jobs, so the shipped 40 / 50 ms would turn a CPU stall into
    a (correct) link-loss stop; this test is about motion, not timing."""
    robot_file = robot_copy("extensible", tmp_path,
                            {"bridge.watchdog_ms": 500, "bridge.link_timeout_ms": 500},
                            name="extensible")
    url = console_server(str(robot_file), "--data-dir", str(tmp_path / "runs"), hardware=None)
    yield url
    assert "device emulator on a pseudo-terminal" in console_server.log(url)  # the default


def link_text(page) -> str:
    """The Hardware panel's link line (the runner's ``bridge_controls.health()``) while the
    Hardware tab is open, else the header's (both from the same health)."""
    link = page.get_by_text("Link:")
    return link.last.locator("xpath=..").inner_text() if link.count() else "no link line"


def test_emulator_console_measured_tip_reaches_a_typed_target(
        page, emulator_console: str, console_server: Any, artifacts_dir: Path) -> None:
    open_extensible(page, emulator_console)
    # The operator connects and arms the emulator's pty through the Hardware panel (the
    # runner's bridge_controls). serve.py connected the link at start, disarmed (connecting
    # never arms); connecting again makes the test about the motion, and about those controls.
    open_tab(page, "Hardware")
    page.get_by_role("button", name="Connect", exact=True).click()
    wait_until("the link configured", lambda: "inactive" in link_text(page), timeout=20,
               show=lambda: link_text(page))
    assert "/dev/pts/" in link_text(page)
    page.get_by_role("button", name="Arm device", exact=True).click()
    wait_until("the link armed", lambda: "ARMED" in link_text(page), timeout=20,
               show=lambda: link_text(page))
    open_tab(page, "Operate")
    # The emulated arm powers up at the console's start pose (--mid-range: straight, racks at
    # mid-range) and Arm holds where it is: nothing moved.
    initial = dk.tip_position(ROBOT, ExtensibleModel(ROBOT).initial()) * 1e3
    seen = [readout_tip(page)]

    def still() -> bool:
        time.sleep(0.3)
        seen.append(readout_tip(page))
        return bool(np.abs(seen[-1] - seen[-2]).max() <= 0.05)
    wait_until("the measured tip held still", still, timeout=20)
    start = seen[-1]
    assert np.abs(start - initial).max() <= 0.5
    # Aim far from it, so the readout has a long way to show the arm on (mm; each candidate is
    # reachable).
    candidates = [np.array(c) for c in ((80.0, 40.0, 300.0), (80.0, 40.0, 180.0),
                                        (60.0, -40.0, 420.0))]
    target = max(candidates, key=lambda c: float(np.linalg.norm(c - start)))
    assert np.linalg.norm(target - start) > 100.0
    ik = solve_tip_ik(ROBOT, target / 1e3)
    assert ik.reachable
    t0 = time.monotonic()
    type_target(page, target)
    samples: list[np.ndarray] = []

    def arrived() -> bool:
        samples.append(readout_tip(page))
        return bool(np.abs(samples[-1] - target).max() <= 1.0)

    status = page.locator('[data-testid="target-status"]')
    wait_until("the measured tip at the target", arrived, timeout=60,
               show=lambda: f"(readout {samples[-1] if samples else None}; target panel: "
                            f"{status.inner_text()!r}; {link_text(page)}; "
                            f"log: {console_server.log(emulator_console)[-600:]})")
    elapsed = time.monotonic() - t0
    # Encoder-driven: the motors take time. The measured tip cannot cover the distance faster
    # than the tip speed limit, and the readout showed it on the way (not a jump to the target).
    distance = float(np.linalg.norm(target - start)) / 1e3
    assert elapsed >= 0.9 * distance / ROBOT.tip_speed, elapsed
    on_the_way = [p for p in samples if np.linalg.norm(p - start) > 20.0
                  and np.linalg.norm(p - target) > 20.0]
    assert on_the_way, "the readout never showed the arm between start and target"
    assert status.get_attribute("data-state") == "reachable"
    time.sleep(0.5)  # settled: the encoders hold there
    assert np.abs(readout_tip(page) - target).max() <= 1.0
    page.screenshot(path=str(artifacts_dir / "browser_extensible_emulator_target.png"))
