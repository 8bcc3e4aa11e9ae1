"""Data folder hygiene (traversal attempts refused before any file is touched), recording round
trips (states, actions with who, overlays) and refusing recordings of the wrong robot."""

from __future__ import annotations

import gzip
import os
import time
from pathlib import Path

import numpy as np
import pytest

from console.core.datadir import BadFileName, DataDir
from console.core.model import model_for
from console.recording.recorder import SUFFIX, Recorder, load_recording
from console.core.state import StateStore
from core.robots import load

SOFT = load("soft-arm")
EXT = load("extensible")

TRAVERSALS = [
    "../escape.jsonl.gz", "../../etc/passwd", "/etc/passwd", "sub/dir.jsonl.gz",
    "..\\escape.jsonl.gz", "..", ".", "", " x.jsonl.gz", ".hidden.jsonl.gz",
    "x.jsonl.gz\x00.txt", "%2e%2e%2fescape.jsonl.gz", "a..b.jsonl.gz", "~/x.jsonl.gz",
    "x" * 120 + ".jsonl.gz", "run.html", None, 42, "ok name.jsonl.gz",
]


@pytest.mark.parametrize("name", TRAVERSALS)
def test_names_from_the_gui_cannot_leave_the_data_folder(tmp_path: Path, name) -> None:
    data = DataDir(tmp_path / "runs")
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    with pytest.raises(BadFileName):
        data.path("recordings", name, SUFFIX)
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before


def test_a_symlink_planted_in_the_data_folder_is_refused(tmp_path: Path) -> None:
    data = DataDir(tmp_path / "runs")
    outside = tmp_path / "secret.jsonl.gz"
    outside.write_bytes(b"not yours")
    os.symlink(outside, data.folder("recordings") / "link.jsonl.gz")
    with pytest.raises(BadFileName, match="outside"):
        data.path("recordings", "link.jsonl.gz", SUFFIX)
    assert "link.jsonl.gz" not in data.list("recordings", SUFFIX)


def test_plain_names_resolve_inside_and_free_text_stems_are_cleaned(tmp_path: Path) -> None:
    data = DataDir(tmp_path / "runs")
    p = data.path("recordings", "run-1_a.jsonl.gz", SUFFIX)
    assert p == (tmp_path / "runs" / "recordings" / "run-1_a.jsonl.gz").resolve()
    name = data.new_name("recordings", "../../etc/Demo run!", SUFFIX)
    assert "/" not in name and ".." not in name and name.startswith("etc-Demo-run-")
    assert data.path("recordings", name, SUFFIX).parent == data.folder("recordings")
    with pytest.raises(ValueError, match="unknown kind"):
        data.folder("../..")


def test_recording_round_trip_keeps_states_actions_and_overlays(tmp_path: Path) -> None:
    model = model_for(SOFT)
    store = StateStore(model)
    rec = Recorder(DataDir(tmp_path), model, name_of=lambda c: {None: "server", 7: "Alice"}[c])
    path = rec.start("lesson 1", client=7)
    assert path.parent == tmp_path / "recordings" and path.name.startswith("lesson-1-")
    qs = [np.linspace(-i, i, 6) for i in range(5)]
    for q in qs:
        rec.on_state(store.request(q, "jog"))
        time.sleep(0.01)
    rec.action("took control", 7)
    rec.log("overlay", {"name": "plan", "points": np.array([[0, 0, 0], [0.1, 0.2, 0]]),
                        "color": (255, 0, 255)}, 7)
    rec.log("telemetry", {"p99_ms": np.float64(1.5)})
    with pytest.raises(ValueError, match="reserved"):
        rec.log("state", {})
    with pytest.raises(RuntimeError, match="already recording"):
        rec.start()
    assert rec.stop() == path and not rec.recording
    rec.log("action", "after the end")  # no-op when idle

    loaded = load_recording(path, model)
    assert loaded.header["by"] == "Alice" and loaded.header["robot"] == "soft-arm"
    np.testing.assert_allclose(loaded.qs, np.array(qs))
    assert np.all(np.diff(loaded.times) > 0) and loaded.sources == ["jog"] * 5
    kinds = [(e.kind, e.who) for e in loaded.events]
    assert kinds == [("action", "Alice"), ("overlay", "Alice"), ("telemetry", "server")]
    assert loaded.events[0].text == "took control"
    assert loaded.overlays_until(loaded.duration + 1)["plan"]["points"] == [[0, 0, 0],
                                                                          [0.1, 0.2, 0]]
    t_mid = float(loaded.times[2])
    np.testing.assert_allclose(loaded.q_at(t_mid), qs[2])
    np.testing.assert_allclose(loaded.q_at(t_mid - 1e-4), qs[1])
    np.testing.assert_allclose(loaded.q_at(-5.0), qs[0])


def test_wrong_robot_and_broken_files_are_refused_with_a_reason(tmp_path: Path) -> None:
    soft, ext = model_for(SOFT), model_for(EXT)
    rec = Recorder(DataDir(tmp_path), soft)
    path = rec.start("soft")
    rec.on_state(StateStore(soft).request(np.ones(6), "jog"))
    rec.stop()
    with pytest.raises(ValueError, match="recorded on 'soft-arm'"):
        load_recording(path, ext)
    broken = tmp_path / "recordings" / "broken.jsonl.gz"
    broken.write_bytes(b"this is not gzip")
    with pytest.raises(ValueError, match="cannot read"):
        load_recording(broken, soft)
    foreign = tmp_path / "recordings" / "foreign.jsonl.gz"
    with gzip.open(foreign, "wt") as f:
        f.write('{"kind": "header", "format": "something-else"}\n')
    with pytest.raises(ValueError, match="not a console recording"):
        load_recording(foreign, soft)
    empty = Recorder(DataDir(tmp_path), soft)
    p = empty.start("empty")
    empty.stop()
    with pytest.raises(ValueError, match="no arm states"):
        load_recording(p, soft)
