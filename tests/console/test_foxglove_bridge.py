"""Live bridge: a websocket client speaking the Foxglove WebSocket protocol
(``foxglove.websocket.v1``, or the same messages under foxglove-sdk's ``foxglove.sdk.v1``) gets
``serverInfo`` with no capabilities, the advertised lab channels with their schema names, and messages while the
arm moves; publishing, service calls and parameter writes from the client move nothing.
``serve.py --foxglove-port`` starts it (off by default)."""

from __future__ import annotations

import json
import logging
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import pytest
import viser
from websockets.sync.client import ClientConnection, connect

from console.app import ConsoleApp
from console.recording.foxglove_bridge import FoxgloveBridge
from core.labdata.channels import CHANNELS
from core.robots import load

SOFT = load("soft-arm")
REPO = Path(__file__).resolve().parents[2]
SUBPROTOCOL = "foxglove.websocket.v1"


@pytest.fixture
def live(tmp_path: Path) -> Iterator[tuple[ConsoleApp, FoxgloveBridge]]:
    srv = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    app = ConsoleApp(SOFT, srv, data_dir=tmp_path)
    bridge = FoxgloveBridge(app.recorder, SOFT, "127.0.0.1", 0)
    try:
        with app:
            yield app, bridge
    finally:
        bridge.stop()
        srv.stop()


def hello(ws: ClientConnection) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """serverInfo and the advertised channels by topic."""
    info = json.loads(ws.recv(timeout=5))
    channels: dict[str, dict[str, Any]] = {}
    while len(channels) < len(CHANNELS):
        msg = json.loads(ws.recv(timeout=5))
        assert msg["op"] == "advertise"
        channels.update({c["topic"]: c for c in msg["channels"]})
    return info, channels


def messages(ws: ClientConnection, until: float) -> Iterator[tuple[int, int, Any]]:
    """(subscription id, log time, JSON body) of messageData frames until ``until``."""
    while time.monotonic() < until:
        try:
            frame = ws.recv(timeout=max(0.01, until - time.monotonic()))
        except TimeoutError:
            return
        if isinstance(frame, bytes) and frame[0] == 0x01:
            sub, ns = struct.unpack_from("<IQ", frame, 1)
            yield sub, ns, json.loads(frame[13:])


@pytest.mark.parametrize("subprotocol", ["foxglove.websocket.v1", "foxglove.sdk.v1"])
def test_client_gets_server_info_channels_and_messages_while_the_arm_moves(live,
                                                                           subprotocol) -> None:
    app, bridge = live
    with connect(f"ws://127.0.0.1:{bridge.port}", subprotocols=[subprotocol]) as ws:
        assert ws.subprotocol == subprotocol
        info, channels = hello(ws)
        assert info["op"] == "serverInfo" and info["name"] == "softarm-console"
        assert info["capabilities"] == []  # no clientPublish, services, parameters, assets
        assert {t: c["schemaName"] for t, c in channels.items()} == \
            {spec.topic: spec.schema_name for spec in CHANNELS}
        assert all(c["encoding"] == "json" and c["schemaEncoding"] == "jsonschema"
                   for c in channels.values())
        assert json.loads(channels["/arm/scene"]["schema"])["title"] == "foxglove.SceneUpdate"
        subs = {1: "/arm/configuration", 2: "/arm/scene", 3: "/events", 4: "/arm/tip"}
        before = time.time_ns()
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": k, "channelId": channels[t]["id"]} for k, t in subs.items()]}))
        time.sleep(0.3)
        targets = [np.full(6, k) for k in (2.0, 4.0, 6.0)]
        for q in targets:
            app.store.request(q, "jog")
            time.sleep(0.1)
        app.stop_motion("test stop")
        got: dict[str, list[tuple[int, Any]]] = {t: [] for t in subs.values()}
        for sub, ns, body in messages(ws, time.monotonic() + 2.0):
            got[subs[sub]].append((ns, body))
        after = time.time_ns()
    seen = [[s["kappa"] for s in body["measured"]] for _, body in got["/arm/configuration"]]
    distinct = [s for i, s in enumerate(seen) if i == 0 or s != seen[i - 1]]
    assert [s for s in distinct if s != [0.0] * 6] == [q.tolist() for q in targets]
    assert got["/arm/scene"] and got["/arm/tip"]
    latched = [ns for ns, _ in got["/arm/configuration"] if ns < before]
    # the configuration drawn before subscribing, sent on subscribe (and once more 0.3 s later
    # for a second subscriber's race: the same record; a fresh run got it twice)
    assert len(set(latched)) <= 1
    assert all(before <= ns <= after for ns, _ in got["/arm/configuration"][len(latched):])
    stamps = [ns for ns, _ in got["/arm/configuration"]]
    assert stamps == sorted(stamps)
    logs = [body for _, body in got["/events"]]
    assert {"level": 3, "message": "STOP: test stop", "name": "server"}.items() <= \
        logs[-1].items()


def test_client_publish_service_calls_and_parameters_move_nothing(live) -> None:
    app, bridge = live
    time.sleep(0.2)
    command, display = app.store.command, app.store.display
    with connect(f"ws://127.0.0.1:{bridge.port}", subprotocols=[SUBPROTOCOL]) as ws:
        hello(ws)
        ws.send(json.dumps({"op": "advertise", "channels": [
            {"id": 7, "topic": "/arm/configuration", "encoding": "json",
             "schemaName": "softarm.Configuration"}]}))
        move = json.dumps({"measured": [{"kappa": 9.0}] * 6, "commanded": [{"kappa": 9.0}] * 6})
        ws.send(b"\x01" + struct.pack("<I", 7) + move.encode())
        ws.send(b"\x02" + struct.pack("<III", 1, 1, 4) + b"json" + move.encode())
        ws.send(json.dumps({"op": "setParameters", "parameters": [{"name": "q", "value": 9}]}))
        replies = []
        deadline = time.monotonic() + 1.5
        while time.monotonic() < deadline:
            try:
                frame = ws.recv(timeout=0.2)
            except TimeoutError:
                continue
            if isinstance(frame, str):
                replies.append(json.loads(frame))
    assert app.store.command is command and app.store.display is display
    assert app.store.command.q.tolist() == [0.0] * 6
    ops = [r["op"] for r in replies]
    assert "serviceCallFailure" in ops  # the server says it has no services
    assert any("clientPublish" in r.get("message", "") for r in replies)


def test_serve_flag_is_off_by_default_and_starts_the_bridge(tmp_path: Path) -> None:
    import serve

    assert serve.parse_args([]).foxglove_port is None
    ports = []
    for _ in range(2):
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            ports.append(s.getsockname()[1])
    proc = subprocess.Popen(
        [sys.executable, str(REPO / "serve.py"), "--robot", "extensible", "--hardware", "mock",
         "--rt-cpu", "none", "--port", str(ports[0]), "--foxglove-port", str(ports[1]),
         "--data-dir", str(tmp_path)],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        line = ""
        for line in proc.stdout:
            if line.startswith("Foxglove live data"):
                break
        assert line.strip() == f"Foxglove live data (read-only): ws://127.0.0.1:{ports[1]}"
        with connect(f"ws://127.0.0.1:{ports[1]}", subprotocols=[SUBPROTOCOL]) as ws:
            info, channels = hello(ws)
        assert info["name"] == "softarm-console" and "/arm/scene" in channels
    finally:
        proc.terminate()
        proc.communicate(timeout=20)
    bad = subprocess.run([sys.executable, str(REPO / "serve.py"), "--foxglove-port", "70000"],
                         cwd=REPO, capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "--foxglove-port must be in 1..65535" in bad.stderr


def test_a_client_joining_while_the_arm_rests_still_gets_its_configuration(live) -> None:
    app, bridge = live
    q = np.array([1.0, -2.0, 3.0, -4.0, 5.0, -6.0])
    app.store.request(q, "jog")
    time.sleep(0.5)  # drawn (and sent to nobody) before anyone connects
    with connect(f"ws://127.0.0.1:{bridge.port}", subprotocols=[SUBPROTOCOL]) as ws:
        _, channels = hello(ws)
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": 1, "channelId": channels["/arm/configuration"]["id"]}]}))
        got = [body for _, _, body in messages(ws, time.monotonic() + 2.5)]
    assert got and [s["kappa"] for s in got[-1]["measured"]] == q.tolist()


PHASE = {"phase": "idle", "reason": "", "armed": False}


def _wait_for_table(app: ConsoleApp) -> list[dict[str, Any]]:
    """The default console's objects (x, y, r in m) once its grasp session planned for them."""
    import dataclasses

    session = app.grasp_session
    assert session is not None
    deadline = time.monotonic() + 30.0
    while time.monotonic() < deadline:
        view = session.view()
        table = [dataclasses.asdict(o) for o in view.objects]
        logged = [r["data"]["objects"] for r in app.recorder.latched()
                  if r.get("kind") == "objects"]
        # Its record is logged by the session's worker after the redraw: wait for it too.
        if table and view.outcome is not None and logged and \
                [(o["x"], o["y"], o["r"]) for o in logged[0]] == \
                [(o["x"], o["y"], o["r"]) for o in table]:
            return table
        time.sleep(0.05)
    raise AssertionError("the default console had no planned, logged object within 30 s")


def test_a_client_joining_mid_run_gets_the_tables_objects_at_once(live) -> None:
    """Latched: the objects logged before the client (and the bridge) existed come with the
    subscription, not after the next change (before: nothing on /objects for 15 s).

    What proves the latch is the messages' log time (before the subscription: a re-send of the
    newest record, not a new one), not how fast they come: a loaded machine may take seconds."""
    app, bridge = live
    table = _wait_for_table(app)
    with connect(f"ws://127.0.0.1:{bridge.port}", subprotocols=[SUBPROTOCOL]) as ws:
        _, channels = hello(ws)
        subscribed_ns = time.time_ns()
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": 1, "channelId": channels["/objects"]["id"]},
            {"id": 2, "channelId": channels["/scene/objects"]["id"]},
            {"id": 3, "channelId": channels["/robot/description"]["id"]}]}))
        got: dict[int, list[Any]] = {1: [], 2: [], 3: []}
        logged: dict[int, list[int]] = {1: [], 2: [], 3: []}
        for sub, ns, body in messages(ws, time.monotonic() + 15.0):
            got[sub].append(body)
            logged[sub].append(ns)
            if all(got.values()):
                break
    assert got[1], "no /objects message within 15 s of subscribing"
    assert got[3], "no /robot/description within 15 s of subscribing"
    assert got[2], "no /scene/objects within 15 s of subscribing"
    assert all(ns[0] < subscribed_ns for ns in logged.values()), \
        "the first messages were logged after the subscription: not the latched state"
    _assert_describes(got[3][0], SOFT)
    assert [(o["x"], o["y"], o["r"]) for o in got[1][0]["objects"]] == \
        [(o["x"], o["y"], o["r"]) for o in table]
    cylinders = [c for e in got[2][0]["entities"] if e["id"] == "objects" for c in e["cylinders"]]
    assert [(c["pose"]["position"]["x"], c["pose"]["position"]["y"], c["size"]["x"])
            for c in cylinders] == [(o["x"], o["y"], 2 * o["r"]) for o in table]


def test_events_carry_no_repeated_phase_while_nothing_happens(live) -> None:
    """/events only when something happens (before: 'phase: idle' about once a second)."""
    app, bridge = live
    _wait_for_table(app)
    app.recorder.log("phase", PHASE)  # what the control feed logs once at start
    time.sleep(0.5)
    with connect(f"ws://127.0.0.1:{bridge.port}", subprotocols=[SUBPROTOCOL]) as ws:
        _, channels = hello(ws)
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": 1, "channelId": channels["/events"]["id"]}]}))
        logs = [body["message"] for _, _, body in messages(ws, time.monotonic() + 3.5)]
    assert [m for m in logs if m.startswith("phase:")] == []


def test_a_recording_started_mid_session_begins_with_the_table(live) -> None:
    """The first messages of a recording started after the table was logged hold its objects
    (read with the independent ``mcap`` reader); the file's format id is the MCAP one."""
    from mcap.reader import make_reader

    from core.labdata.mcap_file import FORMAT, META_NAME

    app, _ = live
    table = _wait_for_table(app)
    app.recorder.log("phase", PHASE)
    time.sleep(0.5)
    path = app.recorder.start("mid")
    time.sleep(0.5)
    app.recorder.stop()
    with open(path, "rb") as f:
        reader = make_reader(f)
        meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        f.seek(0)
        first: dict[str, Any] = {}
        start = int(meta[META_NAME]["start_ns"])
        for _, channel, message in make_reader(f).iter_messages(log_time_order=True):
            if message.log_time == start:
                first.setdefault(channel.topic, json.loads(message.data))
    assert meta[META_NAME]["format"] == FORMAT == "softarm-console-mcap/1"
    assert [(o["x"], o["y"], o["r"]) for o in first["/objects"]["objects"]] == \
        [(o["x"], o["y"], o["r"]) for o in table]
    assert "/scene/objects" in first and "/plan" in first and "/scene/plan" in first
    assert first["/control/phase"]["phase"] == "idle"
    _assert_describes(first["/robot/description"], SOFT)


def _assert_describes(message: dict[str, Any], robot: Any) -> None:
    """``message`` carries ``robot``'s file: its text, read back by the robot parser."""
    from core.robot_schema import tomllib
    from core.robots import parse

    assert message["name"] == robot.name and message["kind"] == robot.kind
    assert message["toml"] == robot.source.read_text(encoding="utf-8")
    again = parse(tomllib.loads(message["toml"]), message["file"])
    assert again.n_segments == robot.n_segments and again.name == robot.name


def test_a_client_unsubscribing_and_leaving_logs_no_callback_failure(live, caplog) -> None:
    """The SDK calls on_unsubscribe when a client unsubscribes or leaves (before: each call
    logged "Callback failed: AttributeError: '_Subscriptions' object has no attribute
    'on_unsubscribe'")."""
    _, bridge = live
    with caplog.at_level(logging.DEBUG):
        with connect(f"ws://127.0.0.1:{bridge.port}", subprotocols=[SUBPROTOCOL]) as ws:
            _, channels = hello(ws)
            ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                {"id": 1, "channelId": channels["/objects"]["id"]},
                {"id": 2, "channelId": channels["/events"]["id"]}]}))
            ws.send(json.dumps({"op": "unsubscribe", "subscriptionIds": [1]}))
            list(messages(ws, time.monotonic() + 0.5))
        # The SDK's callbacks run on its own threads: wait until it has dropped the client's
        # sinks (it calls on_unsubscribe with that), then a little for the callbacks' logs.
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline and any(
                bridge._channels[t].has_sinks() for t in ("/objects", "/events")):
            time.sleep(0.05)
        time.sleep(0.5)
    failed = [r.getMessage() for r in caplog.records if "Callback failed" in r.getMessage()]
    assert failed == []
