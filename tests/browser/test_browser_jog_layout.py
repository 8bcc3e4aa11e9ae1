"""The Jog panel in a real browser (issue 18): each slider's hold-to-jog − / + sit on the
slider's own row, the soft arm's six rows fit in one screen at 1600x1000, and holding a row's
+ with the mouse jogs that coordinate until it is let go."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pytest

from browser_tabs import open_tab
from console.app import ConsoleApp
from console.panel_sets import DEFAULT_PANELS
from console.core.hold_to_run import HOLD_SOURCE
from console.panels.common.jog import JogPanel
from core.robots import load

# alone: a held jog ends within 0.6 s of the release (expiry 0.3 s) (conftest's SUITE_PART=alone)
pytestmark = [pytest.mark.browser, pytest.mark.alone]


@pytest.fixture(params=["soft-arm", "extensible"])
def jog_page(request: Any, browser: Any, server: Any) -> Iterator[tuple[Any, ConsoleApp]]:
    app = ConsoleApp(load(request.param), server, panels=DEFAULT_PANELS)
    app.start()
    context = browser.new_context(viewport={"width": 1600, "height": 1000})
    try:
        page = context.new_page()
        page.set_default_timeout(60_000)
        page.goto(f"http://127.0.0.1:{server.get_port()}/")
        open_tab(page, "Operate", 60_000)
        page.get_by_text("Jog", exact=True).first.wait_for()
        yield page, app
    finally:
        context.close()
        app.stop()


def _box(page: Any, handle: Any) -> dict[str, float]:
    box = page.locator(f'[id="{handle._impl.uuid}"]').bounding_box()
    assert box is not None
    return box


def test_each_sliders_buttons_sit_on_its_row_and_hold_jogs(jog_page, artifacts_dir: Path) -> None:
    page, app = jog_page
    jog = app.panel(JogPanel)
    page.locator(f'[id="{jog.rows[-1].plus._impl.uuid}"]').wait_for()
    rows = []
    for row in jog.rows:
        track, minus, plus = (_box(page, h) for h in (row.slider, row.minus, row.plus))
        # Same row: the buttons overlap the slider's track vertically, to its right, − first.
        for b in (minus, plus):
            assert b["y"] <= track["y"] + track["height"] and b["y"] + b["height"] >= track["y"]
        assert track["x"] + track["width"] < minus["x"] < plus["x"]
        assert track["width"] > 50, f"{row.coord.label}: track too short to use"
        rows.append(minus["y"])
    assert rows == sorted(rows) and len(set(np.round(rows))) == len(rows)  # one row each
    top = _box(page, jog.rows[0].slider)["y"]
    bottom = _box(page, jog.straighten)["y"] + _box(page, jog.straighten)["height"]
    assert bottom - top < 450, "the Jog rows should fit well inside one 1000 px screen"
    page.mouse.move(5, 5)
    page.screenshot(path=str(artifacts_dir / f"browser_jog_{app.robot.kind}.png"))

    # Hold κ₁'s (δL₁'s) + with the mouse: it jogs that coordinate; letting go stops it.
    row = next(r for r in jog.rows if r.coord.key in ("kappa1", "dL1"))
    plus = _box(page, row.plus)
    page.mouse.move(plus["x"] + plus["width"] / 2, plus["y"] + plus["height"] / 2)
    # This browser takes control (no token) just before: a software-rendered tab on a loaded
    # machine can go silent for 2 s while drawing and lose it.
    (client_id,) = app.server.get_clients()
    app.access.take(client_id, None, "tester")
    probes = app.lease.probes
    deadline = time.monotonic() + 30.0
    while app.lease.probes < probes + 3 and time.monotonic() < deadline:
        time.sleep(0.05)  # the tab answers the lease probes: it holds control
    stops = app.core.stop_log  # (shown if the hold never ran)
    page.mouse.down()
    seen = set()
    deadline = time.monotonic() + 10.0
    while HOLD_SOURCE not in seen and time.monotonic() < deadline:
        seen.add(app.store.command.source)
        time.sleep(0.01)
    time.sleep(0.5)
    page.mouse.up()
    assert HOLD_SOURCE in seen, (seen, stops)
    time.sleep(0.6)  # expiry 0.3 s, or the release click ends it sooner
    last = app.store.command
    assert np.asarray(last.q)[row.coord.index] > 0.0
    time.sleep(0.3)
    assert app.store.command.seq == last.seq and not app.hold.active
