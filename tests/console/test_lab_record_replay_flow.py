"""Record, replay and export a run through the Session panel's widgets, without a browser: the
operator records the demo motion and a STOP; a viewer replays it in their own replay widgets
(per browser), jumps between its markers and exports it (was the GUI part of
tests/browser/test_browser_lab_export.py, which keeps only what the exported page draws).

Two raw websocket clients are the operator's and the viewer's tabs (real connections: each gets
its own replay widgets, and they answer the lease's probes); their clicks reach the panels'
callbacks as viser's would (``fakes.user``). Independent expectations: the recorded events
name the operator and the STOP; the ghost arm at the end of the replay is the planar forward
kinematics of the recorded configuration; the markers are where the jumps land, and the
exported page lists them; the arm's command is still the STOP's after replay and export.
"""

from __future__ import annotations

import re
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import viser

from console.core.access import AccessControl
from console.panels.common.session import SessionPanel
from console.playback.export import external_urls
from console.playback.replay_markers import current_marker, next_marker, previous_marker
from core.kinematics import planar as pk
from core.robots import load
from fakes import FakeClient, console_app, user
from tests.ws_client import RawClient, wait_for

SOFT = load("soft-arm")


@pytest.fixture
def lab(tmp_path: Path) -> Iterator[Any]:
    """A lab console (token, demo motion) with the Session panel, started."""
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    app = console_app(SOFT, server, panels=(SessionPanel,), demo=True,
                      access=AccessControl("tok"), data_dir=tmp_path / "runs")
    app.start()
    try:
        yield app
    finally:
        app.stop_motion("test over")
        app.stop()
        app.panel(SessionPanel).close()
        server.stop()


def tip_of(session: Any) -> np.ndarray:
    """The ghost arm's drawn tip (x, y): the last ring's centre of its body mesh."""
    body = np.asarray(session.ghost.body.vertices, dtype=float)
    k, m = session.ghost.body_topology.sides, session.ghost.body_topology.n_rings
    return body[: m * k].reshape(m, k, 3).mean(axis=1)[-1, :2]


def test_operator_records_a_run_and_a_viewer_replays_jumps_and_exports_it(lab: Any) -> None:
    app = lab
    panel = app.panel(SessionPanel)
    alice_tab, bob_tab = RawClient(app.server), RawClient(app.server)
    try:
        alice, bob = FakeClient(alice_tab.client_id), FakeClient(bob_tab.client_id)
        app.access.take(alice.client_id, "tok", name="Alice")
        wait_for(lambda: bob.client_id in panel.player.sessions, what="Bob's replay widgets")
        session = panel.player.sessions[bob.client_id]
        assert session is not panel.player.sessions[alice.client_id]  # per browser

        # Alice records the demo motion and a STOP.
        user(panel.rec_btn, alice)
        assert app.recorder.recording and panel.rec_btn.label == "Stop recording"
        user(panel.demo_btn, alice)
        wait_for(lambda: app.services.demo.running and app.store.command.source == "demo")
        seq = app.store.command.seq
        wait_for(lambda: app.store.command.seq > seq + 20, what="the demo moving")
        time.sleep(0.6)  # a recording over half a second long
        user(app.header.stop_btn, alice)
        wait_for(lambda: not app.services.demo.running and app.store.command.source == "stop")
        user(panel.rec_btn, alice)
        assert not app.recorder.recording
        (name,) = app.data.list("recordings", ".mcap")
        assert name in session.files.options  # the viewer's list is refreshed
        stopped = app.store.command

        # Bob, a viewer, loads and plays it.
        assert not app.access.is_operator(bob.client_id)
        user(session.files, bob, name)
        user(session.load_btn, bob)
        rec = wait_for(lambda: session.rec, what="the recording loaded")
        assert name in session.info.content
        # which arm in the 3D view is the recording's: said under the name, at the position
        # (once drawn: the line says "loading …" until then)
        wait_for(lambda: (f"translucent grey arm with the objects, bin and plan as recorded at "
                          f"{session.pos:.1f} s") in session.info.content,
                 what="the replay's legend line")
        assert rec.duration > 0.5 and any("STOP" in e.text for e in rec.events)
        assert any(e.who == "Alice" and "demo" in e.text for e in rec.events)
        user(session.play_btn, bob)
        wait_for(lambda: session.playing, what="playing")
        wait_for(lambda: not session.playing, timeout=30.0, what="the replay ran to its end")
        assert session.pos == pytest.approx(rec.duration)
        tip = pk.forward_kinematics(rec.q_at(session.pos), SOFT.lengths, SOFT.base_pose)[-1]
        np.testing.assert_allclose(tip_of(session), tip[:2], atol=1e-5)
        assert app.store.command is stopped  # replay never commands the arm

        # Markers (started recording, the demo, STOP, ...): from the end, back two and on one.
        markers = session.markers
        assert len(markers) >= 3 and any(m.category == "stop" for m in markers)
        pos = session.pos
        for button in (session.prev_btn, session.prev_btn, session.next_btn):
            find = previous_marker if button is session.prev_btn else next_marker
            target = find(markers, pos)
            assert target is not None
            pos = min(target.t, rec.duration)
            index = current_marker(markers, pos)[0]
            user(button, bob)
            assert session.pos == pytest.approx(pos, abs=1e-6)
            assert f'data-index="{index}"' in session.info.content
            assert markers[index].text in session.info.content
            np.testing.assert_allclose(tip_of(session), pk.forward_kinematics(
                rec.q_at(pos), SOFT.lengths, SOFT.base_pose)[-1, :2], atol=1e-5)
        assert app.store.command is stopped

        # Bob exports the run: a file in the data folder, the markers listed in it.
        user(session.export_btn, bob)
        (exported,) = app.data.folder("exports").glob("*.html")
        page = exported.read_text(encoding="utf-8")
        listed = re.findall(r'<li data-t="([0-9.]+)" data-category="(\w+)"', page)
        assert [(float(t), c) for t, c in listed] == [(round(m.t, 3), m.category)
                                                      for m in markers]
        assert external_urls(page) == []  # opens offline
        assert not any(title == "Not allowed" for title, _ in bob.notes + alice.notes)
        assert app.store.command is stopped
    finally:
        alice_tab.close()
        bob_tab.close()
