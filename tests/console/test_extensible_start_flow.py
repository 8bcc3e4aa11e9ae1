"""On the default extensible console every action from the start pose moves the arm or says why
not, without a browser.

``serve.build`` for the shipped extensible arm on the in-process mock, a raw websocket tab holding
the lease (typing, holding a jog button as the browser does) and FakeClient clicks with that tab's
id. From the start pose (``ExtensibleModel.initial``: straight, racks at mid-range) the header says
idle; a held Δx₁ + jog moves the tip (at start it used to be refused: retracted, every rack at
rack_min); a typed target is shown pending by the field's own callback (nothing moves), and Go
reaches it;
Preview draws the requested path at once and ends in a planned preview; after Retract a held
Δx₁ − is clamped with a note; nothing shown reads "-0". Was the flow of
tests/browser/test_browser_jog.py, which keeps the page's hold buttons and what the
page draws.
"""

from __future__ import annotations

import re
import time
from typing import Any, Callable

import numpy as np
import viser
from test_extensible_console_flows import (  # noqa: F401 (fixtures)
    attr,
    panels,
    readout_tip,
    served,
    tab,
)
from viser import _messages

from console.core.model import ExtensibleModel
from console.panels.common.jog import HOLD_HZ
from core.kinematics import delta as dk
from core.kinematics.delta_ik import solve_tip_ik
from core.robots import load
from fakes import FakeClient, user
from tests.ws_client import RawClient, wait_for

ROBOT = load("extensible")
NEGATIVE_ZERO = re.compile(r"(?<![\d.])[-−]0(?:\.0+)?(?![\d.])")


def hold(client: RawClient, button: viser.GuiButtonHandle, seconds: float) -> None:
    """What a browser sends while the button is pressed, then the release (a click)."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        client.send(_messages.GuiButtonHoldMessage(button._impl.uuid, HOLD_HZ))
        time.sleep(1.0 / HOLD_HZ)
    client.update(button._impl.uuid, value=True)


def shown_text(app: Any, *handles: Any) -> str:
    """The text of the header and of the given HTML / markdown handles, tags removed."""
    texts = [app.header.status.content, *(h.content for h in handles)]
    return "\n".join(re.sub(r"<[^>]+>", " ", t) for t in texts)


def test_every_action_moves_or_says_why_from_the_start_pose(tab: Callable[..., Any]) -> None:
    app, client = tab("extensible", "mock")
    target, readout, jog, paths, _ = panels(app)
    operator = FakeClient(client.client_id)
    # The start: the loop process has connected its (mock) device. Its connection makes the
    # device's posture the console's command (hw_bridge.extensible_link: the hardware's truth),
    # so a jog sent before it was put back on the start pose on a loaded machine (fresh69: the
    # typed target's move cancelled, the target back on the start tip).
    runner = app.services.extensible_runner
    assert runner is not None and runner.connecting is not None
    assert runner.connecting.result(120) is None
    start = dk.tip_position(ROBOT, ExtensibleModel(ROBOT).initial()) * 1e3
    wait_for(lambda: np.abs(readout_tip(readout) - start).max() <= 0.5, timeout=30.0,
             what="the readout at the start pose")
    wait_for(lambda: ">idle<" in app.header.status.content.replace("</span>", "<"),
             what=lambda: f"the header's phase idle ({app.header.status.content})")

    # A bend jog moves at start.
    dx1 = next(r for r in jog.rows if r.coord.key == "dx1")
    hold(client, dx1.plus, 1.0)
    wait_for(lambda: np.linalg.norm(readout_tip(readout) - start) > 2.0, timeout=30.0,
             what=lambda: f"the tip moved by the bend jog ({jog.note.content})")
    wait_for(lambda: not app.hold.active, timeout=30.0, what="the jog to end")
    assert np.asarray(app.store.command.q)[0, 0] > 0.0  # Δx₁, the way of the button

    # A typed target is answered by the field's callback itself (pending: nothing moves until
    # Go), then Go reaches it.
    aim = np.array([0.0, 0.0, 250.0])
    assert solve_tip_ik(ROBOT, aim / 1e3).reachable
    x_in, y_in, z_in = target.inputs
    x_in._impl.value, y_in._impl.value = 0.0, 0.0  # typed, their callbacks not yet run
    seq = app.store.command.seq
    user(z_in, operator, 250.0)
    assert attr(target.status.content, "data-state") == "pending", target.status.content
    assert attr(target.status.content, "data-pending-mm") == "0.0,0.0,250.0"
    assert app.store.command.seq == seq and app.hold.target() is None  # nothing moved
    user(target.go, operator)
    assert attr(target.status.content, "data-target-mm") == "0.0,0.0,250.0"
    assert attr(target.status.content, "data-state") != "pending", target.status.content
    wait_for(lambda: np.abs(readout_tip(readout) - aim).max() <= 1.0, timeout=40.0,
             what=lambda: f"the tip at the typed target ({target.status.content})")
    assert attr(target.status.content, "data-state") == "reachable", target.status.content

    # Preview draws the requested path at once (before the plan), and ends planned.
    user(paths.preview_btn, operator)
    assert attr(paths.status.content, "data-drawn") == "requested" or attr(
        paths.status.content, "data-state") in ("previewed", "infeasible", "error")
    wait_for(lambda: attr(paths.status.content, "data-state") != "planning", timeout=60.0,
             what="the plan")
    assert attr(paths.status.content, "data-state") == "previewed", paths.status.content

    # A clamp: retracted, every rack at rack_min, a bend is refused with a note, never "-0".
    assert jog.retract is not None
    user(jog.retract, operator)
    retracted = np.array([0.0, 0.0, ROBOT.n_segments * ROBOT.L0 * 1e3])
    wait_for(lambda: np.abs(readout_tip(readout) - retracted).max() <= 0.5, timeout=30.0,
             what="the arm retracted")
    # ... all the way (the jog speed streams it there): a rack a hair above its minimum allows
    # a hair of bend, and the note then names that rack's limit instead (a fresh clone's run)
    wait_for(lambda: np.abs(np.asarray(app.store.command.q)).max() == 0.0, timeout=30.0,
             what=lambda: f"every rack at its minimum ({app.store.command.q})")
    hold(client, dx1.minus, 0.5)
    wait_for(lambda: "clamped to +0 mm" in jog.note.content, timeout=30.0,
             what=lambda: f"the clamp note ({jog.note.content!r})")
    assert "extend δL₁ first" in jog.note.content
    text = shown_text(app, readout.html, target.status, paths.status, jog.note)
    assert not NEGATIVE_ZERO.findall(text), [ln for ln in text.splitlines()
                                             if NEGATIVE_ZERO.search(ln)]
    assert np.abs(readout_tip(readout) - retracted).max() <= 0.5  # the clamp moved nothing
