"""Replay timeline markers: phase changes, faults, STOP and operator actions of an MCAP
recording become slider marks; next/previous jump to them (the ghost shows the configuration
recorded at that moment); the exported run keeps them (a scene label that changes at each
marker's time, and a list in the page)."""

from __future__ import annotations

import re
import time
from pathlib import Path

import numpy as np
import pytest
import viser

from fakes import ScopedClient, console_app
from console.app import ConsoleApp
from console.recording.recorder import Recorder
from console.playback.replay import ReplaySession
from console.web.widgets import slider_marks
from core.robots import load
from test_lab_export import decode_embedded

SOFT = load("soft-arm")



@pytest.fixture
def app(server: viser.ViserServer, tmp_path: Path) -> ConsoleApp:
    return console_app(SOFT, server, data_dir=tmp_path / "runs")  # (conftest's server)


def record(app: ConsoleApp) -> tuple[str, list[np.ndarray]]:
    rec = Recorder(app.data, app.model, name_of=lambda c: {None: "server", 5: "Bea"}[c])
    path = rec.start("markers", client=5)
    qs = [np.full(6, k) for k in (0.0, 2.0, 4.0, 6.0, 8.0, 10.0)]
    events = [lambda: rec.action("took control", 5),
              lambda: rec.log("phase", {"phase": "approach", "reason": None}),
              lambda: rec.log("timing", {"period_ms": 10.0}),  # not a marker
              lambda: rec.log("fault", {"fault": "link lost"}),
              lambda: rec.action("STOP: STOP pressed by Bea", 5),
              lambda: None]
    for q, event in zip(qs, events):
        rec.on_state(app.store.report(q, "hardware"))
        time.sleep(0.05)
        event()
        time.sleep(0.05)
    rec.stop()
    return path.name, qs


def test_markers_jump_and_show_the_recorded_configuration(app) -> None:
    name, qs = record(app)
    client = ScopedClient(app.server)
    session = ReplaySession(app, client, order=50.0)  # type: ignore[arg-type]
    assert session.prev_btn.disabled and session.next_btn.disabled
    assert session.load(name)
    rec = session.rec
    assert rec is not None
    cats = [(m.category, m.who) for m in session.markers]
    assert cats == [("action", "Bea"), ("phase", "server"), ("fault", "server"),
                    ("stop", "Bea")]
    assert [m.text for m in session.markers] == ["Took control by Bea", "Phase: approach",
                                                 "Fault: link lost", "STOP pressed by Bea"]
    assert list(slider_marks(session.timeline)) == \
        [round(m.t, 3) for m in session.markers]
    assert not session.next_btn.disabled
    visited = []
    session.seek(0.0)
    while (m := session.jump(+1)) is not None:
        visited.append(m)
        assert session.pos == pytest.approx(m.t)
        # each marker was logged between two states: the ghost shows the state before it
        k = int(np.searchsorted(rec.times, m.t, side="right")) - 1
        np.testing.assert_allclose(rec.q_at(session.pos), qs[k])
        assert f'data-index="{len(visited) - 1}"' in session.info.content
        assert m.text in session.info.content
    assert visited == session.markers
    assert session.jump(-1) == session.markers[2]
    assert session.jump(-1) == session.markers[1]
    session.seek(0.0)
    assert session.jump(-1) is None and session.pos == 0.0
    assert app.store.command.seq == 0  # replay never commands the arm

    session.export()
    ((file, page),) = client.downloads
    html = page.decode()
    listed = re.findall(r'<li data-t="([0-9.]+)" data-category="(\w+)"', html)
    assert [(float(t), c) for t, c in listed] == [(round(m.t, 3), m.category)
                                                  for m in session.markers]
    payload, _ = decode_embedded(html)
    labels = [(t, (msg.get("updates") or msg.get("props") or {}).get("text"))
              for t, msg in payload["messages"] if msg.get("name") == "/markers/label"]
    texts = [(t, text) for t, text in labels if text]
    assert [text for _, text in texts] == [m.label for m in session.markers]
    for (t, _), m in zip(texts, session.markers):
        assert t == pytest.approx(m.t, abs=1e-6)
