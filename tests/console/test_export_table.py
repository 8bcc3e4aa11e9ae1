"""HTML exports show the table the operator saw: obstacles (with their clearance rings), the bin
and the objects -- in a recorded run's export at the times they were recorded, and in the live
scene's export.

Read back independently: the exported file's embedded scene is decoded (base64, zstd, msgpack)
and the nodes' positions, mesh radii and ring radii are compared with what was recorded.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
import viser

from console.core.datadir import DataDir
from console.playback.export import external_urls, recording_html, scene_html
from console.recording.lab_feed import feed_grasp
from console.core.model import model_for
from console.panels.soft_arm import planner
from console.panels.soft_arm.objects import ObjectsPanel
from console.core.grasp_state import SessionView
from console.recording.recorder import Recorder, load_recording
from console.core.state import StateStore
from console.core.table_bin import TableBin
from console.core.table_scene import TableObject
from core.planning.obstacles import Obstacle
from core.robots import load
from tests.console.test_lab_export import decode_embedded
from tests.fakes import console_app
from tests.ws_client import wait_for

SOFT = load("soft-arm")
CUP = TableObject("cup", -0.20, 0.20, 0.0165)
POST = Obstacle("Post", -0.07, 0.21, 0.015)
MOVED = Obstacle("Post", -0.05, 0.30, 0.02)
BIN = TableBin(0.15, 0.25, (0.0,) * 6, 0.05)
CLEARANCE = 0.012


def messages(payload, name):
    return [(t, m) for t, m in payload["messages"] if m.get("name") == name]


def positions(payload, name):
    """(time, (x, y, z)) of every position the file gives node ``name``."""
    return [(t, tuple(m["position"])) for t, m in messages(payload, name)
            if m["type"] == "SetPositionMessage"]


def binary(payload, buffers, name, prop, width):
    """The last binary ``prop`` array of node ``name`` as rows of ``width`` floats."""
    found = None
    for _, m in messages(payload, name):
        value = (m.get("props") or {}).get(prop)
        if isinstance(value, dict) and "__binary_index" in value:
            found = np.frombuffer(buffers[value["__binary_index"]],
                                  dtype=np.dtype(value["dtype"])).reshape(-1, width)
    assert found is not None, f"no {prop} for {name}"
    return found.astype(float)


def test_a_recorded_run_export_draws_its_obstacles_bin_and_objects(tmp_path):
    model = model_for(SOFT)
    rec = Recorder(DataDir(tmp_path), model)
    path = rec.start("table")
    store = StateStore(model)
    rec.on_state(store.request(np.zeros(6), "init"))
    view = SessionView((CUP,), "cup", None, 0, False, 1.0, False, None, bin=BIN,
                       obstacles=(POST,), clearance=CLEARANCE)
    feed_grasp(rec, view, {"objects", "obstacles"})
    time.sleep(0.4)
    rec.on_state(store.request(np.full(6, 2.0), "jog"))
    feed_grasp(rec, SessionView((CUP,), "cup", None, 0, False, 1.0, False, None, bin=BIN,
                                obstacles=(MOVED,), clearance=CLEARANCE), {"obstacles"})
    time.sleep(0.4)
    rec.on_state(store.request(np.full(6, 4.0), "jog"))
    rec.stop()
    loaded = load_recording(path, model)
    page = recording_html(SOFT, loaded, fps=10.0)
    assert external_urls(page) == []
    payload, buffers = decode_embedded(page)

    # The obstacle where it was, then where it was moved (0.4 s later), each drawn once.
    body = positions(payload, "/recorded/obstacles/body_0")
    assert [xyz for _, xyz in body] == [pytest.approx((POST.x, POST.y, 0.0)),
                                        pytest.approx((MOVED.x, MOVED.y, 0.0))]
    # at least the 0.4 s slept between them, to a frame at 10 fps (how much more is the
    # machine's scheduling: a loaded run had 0.62 s)
    assert body[1][0] - body[0][0] >= 0.4 - 0.1
    # Its body has the last obstacle's radius; its ring is the radius plus the clearance.
    verts = binary(payload, buffers, "/recorded/obstacles/body_0", "vertices", 3)
    assert np.hypot(verts[:, 0], verts[:, 1]).max() == pytest.approx(MOVED.r, abs=1e-6)
    pts = binary(payload, buffers, "/recorded/obstacles/lines_0", "points", 3)
    d = np.hypot(pts[:, 0] - MOVED.x, pts[:, 1] - MOVED.y)
    assert d.max() == pytest.approx(MOVED.r + CLEARANCE, abs=1e-6)  # the clearance ring
    # The bin (an open box as wide as its drop circle, labelled) and the object.
    assert positions(payload, "/recorded/bin/box")[0][1] == pytest.approx((BIN.x, BIN.y, 0.0))
    box = binary(payload, buffers, "/recorded/bin/box", "vertices", 3)
    assert np.abs(box[:, :2]).max() == pytest.approx(BIN.drop_radius, abs=1e-6)
    assert any(m.get("props", {}).get("text") == "Bin"
               for _, m in messages(payload, "/recorded/bin/label"))
    assert positions(payload, "/recorded/objects/body_0")[0][1] == \
        pytest.approx((CUP.x, CUP.y, 0.0))


def test_the_live_scene_export_has_the_obstacles_and_the_bin(monkeypatch):
    monkeypatch.setattr(planner.GraspSession, "compute_reach", False)
    srv = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    app = console_app(SOFT, srv, panels=(ObjectsPanel,))
    s = app.grasp_session
    try:
        s.place_obstacle(POST.x, POST.y, POST.r)
        s.set_clearance(CLEARANCE)
        s.set_bin(BIN)
        layers = app.grasp_scene
        wait_for(lambda: layers.obstacle_layer.bodies and layers.bin_view.shown == BIN, 30.0,
                 "obstacle and bin drawn")
        def exported():  # the clearance rings are drawn a moment after the bodies
            payload, buffers = decode_embedded(scene_html(srv))
            try:
                binary(payload, buffers, "/grasp/obstacles/rings", "points", 3)
            except AssertionError:
                return None
            return payload, buffers

        payload, buffers = wait_for(exported, 30.0, "the clearance rings in the export")
        names = {m.get("name") for _, m in payload["messages"]}
        body = next(n for n in names if str(n).startswith("/grasp/obstacles/body_"))
        assert positions(payload, body)[-1][1] == pytest.approx((POST.x, POST.y, 0.0))
        rings = binary(payload, buffers, "/grasp/obstacles/rings", "points", 3)
        assert np.hypot(rings[:, 0] - POST.x, rings[:, 1] - POST.y).max() == \
            pytest.approx(POST.r + CLEARANCE, abs=1e-6)
        assert positions(payload, "/row/bin/box")[-1][1] == pytest.approx((BIN.x, BIN.y, 0.0))
    finally:
        s.close()
        s._thread.join(5)
        srv.stop()
