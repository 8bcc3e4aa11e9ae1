"""Replays that read (issue 31, item 5): a replay draws the recorded table and plan, its log is
sentences with times, the recording list picks the newest file, and an exported run lists its
markers beside the 3D view, never over it.

Independent expectations: the table is what the test placed and the plan is the one the live
session made (its circles, palm points, and the arm at the grasp by the planar forward
kinematics); the log's times are read from the MCAP file with the ``mcap`` package's own reader
and its sentences written out here by hand; the exported page is parsed with ``html.parser``.
"""

from __future__ import annotations

import json
import os
import re
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
import viser
from mcap.reader import make_reader

from fakes import ScopedClient, console_app
from console.app import ConsoleApp
from console.core.table_bin import locate_bin
from console.core.table_scene import TableObject
from console.panels.soft_arm import planner
from console.playback.export import recording_html
from console.playback.replay import ReplaySession
from console.recording.recorder import SUFFIX, Recorder, load_recording
from core.kinematics import planar as pk
from core.planning.obstacles import Obstacle
from core.robots import load
from test_lab_export import decode_embedded
from ws_client import wait_for

SOFT = load("soft-arm")
CUP = TableObject("Cup", -0.20, 0.20, 0.0165)
FAR = Obstacle("Far", 0.30, 0.05, 0.02)
BIN_XY = (-0.12, 0.10)
CLEARANCE = 0.012


@pytest.fixture
def app(server: viser.ViserServer, tmp_path: Path, monkeypatch) -> ConsoleApp:
    monkeypatch.setattr(planner.GraspSession, "compute_reach", False)
    app = console_app(SOFT, server, data_dir=tmp_path / "runs", panels=())
    try:
        yield app
    finally:
        app.stop()


def settled(app: ConsoleApp):
    """The session's outcome once no plan is pending."""
    s = app.grasp_session

    def idle():
        with s._cond:
            return s._request is None and s._outcome is not None and s._outcome
    return wait_for(idle, timeout=60, what="the session idle")


def names(nodes) -> dict[str, object]:
    return {n.name: n for n in nodes}


def test_a_replay_draws_the_recorded_objects_obstacle_bin_and_plan(app) -> None:
    s = app.grasp_session
    s.set_clearance(CLEARANCE)
    s.set_bin(locate_bin(SOFT, *BIN_XY))
    s.set_scene([CUP], [FAR])
    s.request_plan()
    wait_for(lambda: (o := s.view().outcome) and o.obj is not None and o.obj.name == "Cup"
             and (o.plan is None or o.plan.obstacles == (FAR,)), timeout=60,
             what="the cup planned around the obstacle")
    out = settled(app)
    plan = out.plan
    assert plan is not None and out.obj.name == "Cup", out.refusal
    bin_ = s.view().bin
    # The recording starts after the table was set up and planned: it records them at once.
    path = app.recorder.start("table")
    for k in (0.0, 1.0, 2.0):
        app.recorder.on_state(app.store.report(np.full(6, k), "hardware"))
    app.recorder.stop()

    client = ScopedClient(app.server)
    session = ReplaySession(app, client, order=50.0)  # type: ignore[arg-type]
    assert session.load(path.name)
    session.seek(session.rec.duration)  # type: ignore[union-attr]
    table = names(session.recorded.table_nodes)
    root = "/replay/recorded"
    assert table[f"{root}/objects/body_0"].position == pytest.approx((CUP.x, CUP.y, 0.0))
    assert table[f"{root}/obstacles/body_0"].position == pytest.approx((FAR.x, FAR.y, 0.0))
    assert table[f"{root}/bin/box"].position == pytest.approx((bin_.x, bin_.y, 0.0))
    assert table[f"{root}/bin/label"].text == "Bin"
    ring = np.asarray(table[f"{root}/obstacles/lines_0"].points, float).reshape(-1, 3)
    assert np.hypot(ring[:, 0] - FAR.x, ring[:, 1] - FAR.y).max() == \
        pytest.approx(FAR.r + CLEARANCE, abs=1e-5)                    # the clearance ring

    drawn = names(session.recorded.plan_nodes)
    c = np.asarray(plan.center, float)[:2]
    circles = np.asarray(drawn[f"{root}/plan/circles"].points, float).reshape(-1, 3)
    radii = np.unique(np.round(np.hypot(circles[:, 0] - c[0], circles[:, 1] - c[1]), 5))
    np.testing.assert_allclose(radii, np.unique(np.round(plan.radii, 5)), atol=2e-5)
    palms = np.asarray(drawn[f"{root}/plan/palms"].points, float)
    np.testing.assert_allclose(palms[:, :2], np.asarray(plan.palm_poses)[:, :2], atol=2e-4)
    labels = sorted((n.text for name, n in drawn.items() if "/plan/label_" in name), key=int)
    assert labels == [str(k + 1) for k in range(plan.n)]
    # The arm at the grasp: it ends where the gripper of the last waypoint's shape ends.
    tip = pk.forward_kinematics(np.asarray(plan.kappas[-1], float), SOFT.lengths,
                                SOFT.base_pose)[-1]
    end = tip[:2] + SOFT.gripper.length * np.array([np.cos(tip[2]), np.sin(tip[2])])
    arm = np.asarray(drawn[f"{root}/plan/grasp_arm"].points, float)
    np.testing.assert_allclose(arm[-1, 1, :2], end, atol=1e-5)
    np.testing.assert_allclose(arm[0, 0, :2], SOFT.base_pose[:2], atol=1e-6)

    # Before the first record nothing of the table is drawn; from its records on, it is.
    events = session.rec.events  # type: ignore[union-attr]
    first = min(e.t for e in events if e.kind == "objects")
    planned = min(e.t for e in events if e.kind == "plan")
    session.seek(min(first, planned) - 1e-4)
    if min(first, planned) - 1e-4 >= 0:
        assert session.recorded.table_nodes == [] and session.recorded.plan_nodes == []
    session.seek(max(first, planned))
    assert session.recorded.table_nodes and session.recorded.plan_nodes


def shown_log(session: ReplaySession) -> list[str]:
    """The replay's log lines as a person reads them (tags dropped, entities decoded)."""
    block = re.search(r'<div data-testid="replay-log">(.*)</div>', session.info.content, re.S)
    assert block, session.info.content
    rows = re.findall(r"<small>(.*?)</small>", block.group(1))
    return [r.replace("&lt;", "<").replace("&gt;", ">").replace("&amp;", "&") for r in rows]


def test_the_log_reads_as_sentences_at_the_recorded_times(app) -> None:
    rec = Recorder(app.data, app.model, name_of=lambda c: {None: "server", 7: "Bea"}[c])
    path = rec.start("log", client=7)
    link = {"device": "soft-arm", "state": "active", "fault": None, "armed": False, "lost": 0}
    steps = [
        lambda: rec.log("phase", {"phase": "idle", "reason": None, "armed": False}),
        lambda: rec.log("link", link),
        lambda: rec.log("timing", {"tick": 3735, "loop_t": 37.35, "period_ms": 10.0}),
        lambda: rec.action("Bea took control", 7),
        lambda: rec.action("hardware: arm the device", 7),
        lambda: rec.log("phase", {"phase": "approach", "reason": None, "armed": True}),
        lambda: rec.log("link", link),                                    # nothing new
        lambda: rec.log("phase", {"phase": "grasp", "reason": None, "armed": True}),
        lambda: rec.log("link", {**link, "fault": "no STATE for 42 ms"}),
        lambda: rec.log("fault", {"fault": "tracking error 31 mm"}),
        lambda: rec.action("STOP: STOP pressed by Bea", 7),
    ]
    for k, step in enumerate(steps):
        rec.on_state(app.store.report(np.full(6, float(k)), "hardware"))
        step()
    rec.on_state(app.store.report(np.zeros(6), "hardware"))
    rec.stop()

    # The times, read with the mcap package: log time minus the recording's start.
    with open(path, "rb") as f:
        reader = make_reader(f)
        start = next(int(m.metadata["start_ns"]) for m in reader.iter_metadata())
        f.seek(0)
        by_topic: dict[str, list[float]] = {}
        for _, channel, message in make_reader(f).iter_messages(log_time_order=True):
            json.loads(message.data)
            by_topic.setdefault(channel.topic, []).append((message.log_time - start) / 1e9)
    phase, link_t = by_topic["/control/phase"], by_topic["/link/health"]
    acts, fault = by_topic["/operator/actions"], by_topic["/faults"]
    want = [(phase[0], "Phase: idle"), (link_t[0], "Link active"),
            (acts[0], "Bea took control"), (acts[1], "Device armed by Bea"),
            (phase[1], "Armed"), (phase[1], "Phase: idle → approach"),
            (phase[2], "Phase: approach → grasp"),
            (link_t[2], "Link lost: no STATE for 42 ms"),
            (fault[0], "Fault: tracking error 31 mm"), (acts[2], "STOP pressed by Bea")]
    lines = [f"{t:.1f} s  {text}" for t, text in want]

    session = ReplaySession(app, ScopedClient(app.server), order=50.0)  # type: ignore[arg-type]
    assert session.load(path.name)
    assert [(m.t, m.text) for m in session.markers] == want
    for t, _ in want:
        session.seek(t)
        upto = [line for (u, _), line in zip(want, lines) if u <= t]
        assert shown_log(session) == upto[-8:]
    assert "{" not in "".join(shown_log(session))               # no raw JSON left
    session.seek(0.0)
    if want[0][0] > 0.0:
        assert shown_log(session) == ["Log: nothing yet."]


def test_the_list_picks_the_newest_recording(app) -> None:
    def make(stem: str, suffix: str, mtime: float) -> str:
        rec = Recorder(app.data, app.model, suffix=suffix)
        path = rec.start(stem)
        rec.on_state(app.store.report(np.zeros(6), "hardware"))
        rec.stop()
        os.utime(path, (mtime, mtime))
        return path.name

    older = make("older", ".mcap", 1_000_000.0)
    session = ReplaySession(app, ScopedClient(app.server), order=50.0)  # type: ignore[arg-type]
    assert session.files.value == older
    newer = make("newer", ".mcap", 2_000_000.0)
    session.refresh_files()                       # what the Session panel does on "Stop"
    assert session.files.options[:2] == (newer, older) and session.files.value == newer
    # The older format counts by its time as well, not after every .mcap.
    newest = make("newest", SUFFIX, 3_000_000.0)
    fresh = ReplaySession(app, ScopedClient(app.server, cid=98), order=50.0)  # type: ignore
    assert fresh.files.options == (newest, newer, older) and fresh.files.value == newest
    # Picking an older one by hand stays picked while no new recording comes.
    fresh.files.value = older
    fresh.refresh_files()
    assert fresh.files.value == older


class _Page(HTMLParser):
    """The exported page's body children, the marker list's parts and its style sheets."""

    def __init__(self) -> None:
        super().__init__()
        self.stack: list[tuple[str, dict[str, str | None]]] = []
        self.body_children: list[tuple[str, dict[str, str | None]]] = []
        self.in_list: list[str] = []
        self.styles: list[str] = []
        self._style = False

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if self.stack and self.stack[-1][0] == "body":
            self.body_children.append((tag, a))
        if any(t == "details" for t, _ in self.stack) or a.get("id") == "run-markers":
            self.in_list.append(tag)
        self._style = tag == "style"
        if tag not in ("meta", "link", "br", "img", "input"):
            self.stack.append((tag, a))

    def handle_endtag(self, tag):
        while self.stack:
            if self.stack.pop()[0] == tag:
                break
        self._style = False

    def handle_data(self, data):
        if self._style:
            self.styles.append(data)


def rules(css: str, selector: str) -> str:
    """The declarations of every top-level rule of ``css`` whose selector is ``selector``."""
    top = re.sub(r"@media[^{]*\{(?:[^{}]*\{[^{}]*\})*[^{}]*\}", "", css)
    return ";".join(body for sel, body in re.findall(r"([^{}]+)\{([^{}]*)\}", top)
                    if sel.strip() == selector)


def test_an_exported_run_lists_its_markers_beside_the_view(app) -> None:
    rec = Recorder(app.data, app.model)
    path = rec.start("export")
    rec.on_state(app.store.report(np.zeros(6), "hardware"))
    rec.log("phase", {"phase": "idle", "reason": None, "armed": False})
    rec.log("plan", {"refusal": None, "center": [CUP.x, CUP.y], "radius": CUP.r,
                     "circles": [{"x": CUP.x, "y": CUP.y, "r": 0.05}],
                     "waypoints": [{"kappa": [0.0] * 6, "palm": [-0.1, 0.3, 1.0]}]})
    rec.action("STOP: STOP pressed by Bea")
    rec.on_state(app.store.report(np.ones(6), "hardware"))
    rec.stop()
    loaded = load_recording(path, app.model)
    page = recording_html(SOFT, loaded, fps=5.0)

    doc = _Page()
    doc.feed(page)
    tags = [(t, a.get("id")) for t, a in doc.body_children]
    # The list is the body's child right after the view's #root: beside it, not inside it.
    assert ("div", "root") in tags and ("details", "run-markers") in tags
    assert tags.index(("details", "run-markers")) == tags.index(("div", "root")) + 1
    details = dict(doc.body_children)["details"]
    assert "open" in details and "style" not in details      # collapsible; laid out by CSS
    assert doc.in_list[:2] == ["details", "summary"]         # a summary to fold it by
    css = "".join(doc.styles)
    body = rules(css, "html body").replace(" ", "")
    assert "display:flex" in body and "flex-direction:row" in body
    view = rules(css, "html body>#root").replace(" ", "")
    assert "flex:110" in view and "width:auto" in view       # the view takes what is left
    side = rules(css, "#run-markers").replace(" ", "")
    assert "position:static" in side and "flex:00auto" in side
    assert not re.search(r"position:\s*(fixed|absolute)", css.split("run-markers", 1)[1])
    items = re.findall(r'<li data-t="([0-9.]+)"[^>]*>([^<]*)</li>', page)
    words = {"phase": "Phase: idle", "action": "STOP pressed by Bea"}
    told = [(e.t, words[e.kind]) for e in loaded.events if e.kind in words]
    assert [(float(t), text) for t, text in items] == [
        (round(t, 3), f"{t:.1f} s  {w}") for t, w in told]
    # The plan is drawn in the exported scene too.
    payload, _ = decode_embedded(page)
    drawn = {m.get("name") for _, m in payload["messages"]}
    assert {"/recorded/plan/circles", "/recorded/plan/palms", "/recorded/plan/grasp_arm"} <= drawn
