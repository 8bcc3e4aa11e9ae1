"""Replay without a browser: a session refuses file names that leave the data folder, loads a
recording, draws the ghost arm at the seeked time (checked against the planar FK), plays at the
chosen speed, never commands the arm, and exports the run inside the data folder only."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
import viser

from fakes import ScopedClient, console_app
from console.app import ConsoleApp
from console.recording.recorder import Recorder
from console.playback.replay import ReplaySession
from core.kinematics import planar as pk
from core.robots import load

SOFT = load("soft-arm")



@pytest.fixture
def app(server: viser.ViserServer, tmp_path: Path) -> ConsoleApp:
    return console_app(SOFT, server, data_dir=tmp_path / "runs")  # (conftest's server)


def record(app: ConsoleApp) -> tuple[str, list[np.ndarray]]:
    rec = Recorder(app.data, app.model)
    path = rec.start("replay")
    qs = [np.full(6, k) for k in (0.0, 3.0, 6.0, 9.0)]
    for q in qs:
        rec.on_state(app.store.report(q, "hardware"))
        time.sleep(0.05)
    rec.stop()
    return path.name, qs


def tip_of(session: ReplaySession) -> np.ndarray:
    ghost = session.ghost
    body = np.asarray(ghost.body.vertices, dtype=float)  # type: ignore[union-attr]
    k, m = ghost.body_topology.sides, ghost.body_topology.n_rings  # type: ignore[union-attr]
    return body[: m * k].reshape(m, k, 3).mean(axis=1)[-1, :2]


@pytest.mark.parametrize("name", ["../../../etc/passwd", "/etc/passwd",
                                  "../exports/x.jsonl.gz", "missing.jsonl.gz"])
def test_loading_refuses_names_outside_or_missing(app, name: str) -> None:
    client = ScopedClient(app.server)
    session = ReplaySession(app, client, order=50.0)  # type: ignore[arg-type]
    assert not session.load(name)
    assert session.rec is None and session.ghost is None
    assert client.notes and client.notes[-1][0] == "Cannot load recording"


def test_seek_play_and_export_a_recording(app) -> None:
    name, qs = record(app)
    client = ScopedClient(app.server)
    session = ReplaySession(app, client, order=50.0)  # type: ignore[arg-type]
    assert name in session.files.options
    command = app.store.command
    assert session.load(name)
    rec = session.rec
    assert rec is not None and len(rec.times) == 4
    for i in (2, 1, 3):
        session.seek(float(rec.times[i]))
        tip = pk.forward_kinematics(qs[i], SOFT.lengths, SOFT.base_pose)[-1, :2]
        np.testing.assert_allclose(tip_of(session), tip, atol=1e-5)
    session.seek(0.0)
    session.speed = 2.0
    session.toggle()
    session.advance(float(rec.times[2]) / 2.0)  # half the time at double speed
    assert session.pos == pytest.approx(float(rec.times[2]))
    session.advance(10.0)
    assert session.pos == rec.duration and not session.playing  # stops at the end
    assert app.store.command is command  # replay never commands the arm
    session.export()
    exports = list(app.data.folder("exports").glob("*.html"))
    assert len(exports) == 1 and exports[0].name.startswith("replay-")
    assert [(name, len(content)) for name, content in client.downloads] == [
        (exports[0].name, exports[0].stat().st_size)]


def test_a_replay_that_ends_shows_its_last_pose_before_it_says_it_stopped(app) -> None:
    """Whoever sees ``playing`` turn False (a page, a test) sees the arm at the end already: the
    last pose is drawn before the replay says it stopped (a fresh clone's run read the ghost
    between the two and found the previous frame)."""
    name, qs = record(app)
    client = ScopedClient(app.server)
    session = ReplaySession(app, client, order=50.0)  # type: ignore[arg-type]
    assert session.load(name)
    rec = session.rec
    assert rec is not None and session.ghost is not None
    end = pk.forward_kinematics(qs[-1], SOFT.lengths, SOFT.base_pose)[-1, :2]
    seen: list[tuple[bool, bool]] = []  # (still playing, the ghost at the end) per ghost update
    update = session.ghost.update

    def watched(q):  # type: ignore[no-untyped-def]
        update(q)
        seen.append((session.playing, bool(np.allclose(tip_of(session), end, atol=1e-5))))

    session.ghost.update = watched  # type: ignore[method-assign]
    session.toggle()
    session.advance(10.0)
    assert not session.playing and session.pos == rec.duration
    assert seen and seen[-1][1]
    assert (True, True) in seen, seen  # the end drawn while the replay still said "playing"
