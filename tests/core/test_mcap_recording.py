"""MCAP recordings: a console recording read back with the independent ``mcap`` reader (channels,
schema names Foxglove renders, message counts, log times never decreasing, every message valid
against its channel's JSON schema), the tip pose against the closed-form arc, replay of the file
at three times, conversion of an old ``.jsonl.gz`` recording (CLI) and the size of a 10-minute
session."""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from scipy.spatial.transform import Rotation

from console.core.datadir import DataDir
from console.core.model import model_for
from console.recording.recorder import SUFFIX, Recorder, load_recording
from console.core.state import StateStore
from core.labdata import __main__ as labdata_cli
from core.labdata.channels import ArmGeometry, quaternion
from core.labdata.mcap_file import McapLog
from core.robots import load

SOFT = load("soft-arm")
EXT = load("extensible")

WELL_KNOWN = {"/arm/scene": "foxglove.SceneUpdate", "/scene/objects": "foxglove.SceneUpdate",
              "/scene/plan": "foxglove.SceneUpdate", "/scene/overlays": "foxglove.SceneUpdate",
              "/arm/tip": "foxglove.PoseInFrame", "/events": "foxglove.Log",
              "/arm/configuration": "softarm.Configuration", "/objects": "softarm.Objects",
              "/plan": "softarm.Plan", "/control/phase": "softarm.ControlPhase",
              "/control/loop_timing": "softarm.LoopTiming", "/link/health": "softarm.LinkHealth",
              "/operator/actions": "softarm.OperatorAction", "/faults": "softarm.Fault",
              "/console/telemetry": "softarm.Record", "/console/overlay": "softarm.Record"}
_TYPES = {"object": dict, "array": list, "string": str, "boolean": bool, "null": type(None),
          "integer": int, "number": (int, float)}


def check(value: Any, schema: dict[str, Any], where: str = "$") -> None:
    """A small JSON-schema check (type, enum, properties, additionalProperties, items)."""
    types = schema.get("type")
    if types is not None:
        names = [types] if isinstance(types, str) else types
        ok = any(isinstance(value, _TYPES[n]) and not (n in ("integer", "number")
                                                       and isinstance(value, bool))
                 for n in names)
        assert ok, f"{where}: {value!r} is not {names}"
    if "enum" in schema:
        assert value in schema["enum"], f"{where}: {value!r} not in {schema['enum']}"
    if isinstance(value, dict):
        props = schema.get("properties", {})
        if schema.get("additionalProperties") is False:
            assert set(value) <= set(props), f"{where}: extra keys {set(value) - set(props)}"
        for key, sub in props.items():
            if key in value:
                check(value[key], sub, f"{where}.{key}")
    if isinstance(value, list) and "items" in schema:
        for i, item in enumerate(value):
            check(item, schema["items"], f"{where}[{i}]")


def record_session(tmp_path: Path) -> tuple[Path, list[np.ndarray], list[float]]:
    model = model_for(SOFT)
    store = StateStore(model)
    rec = Recorder(DataDir(tmp_path), model, name_of=lambda c: {None: "server", 7: "Alice"}[c])
    path = rec.start("lab", client=7)
    assert path.name.endswith(".mcap")
    qs = [np.full(6, k) for k in (0.0, 2.0, 4.0, 6.0, 8.0)]
    rec.action("took control", 7)
    rec.log("objects", {"objects": [{"name": "cup", "x": -0.2, "y": 0.15, "r": 0.0165}],
                        "selected": "cup"}, 7)
    rec.log("plan", {"center": [-0.2, 0.15], "radius": 0.0165,
                     "circles": [{"x": -0.2, "y": 0.15, "r": 0.05}],
                     "waypoints": [{"kappa": [1.0] * 6, "palm": [-0.1, 0.2, 1.0]},
                                   {"kappa": [2.0] * 6, "palm": [-0.15, 0.18, 1.5]}]}, 7)
    for i, q in enumerate(qs):
        rec.on_state(store.request(q, "jog"), store.request(q + 0.5, "planner"))
        rec.log("timing", {"tick": i, "period_ms": 10.0 + i, "work_ms": 0.4, "overruns": 0})
        time.sleep(0.02)
    rec.log("phase", {"phase": "approach", "reason": None, "armed": True})
    rec.log("link", {"device": "emulator", "state": "active", "armed": True,
                     "rtt_ms_p99": 0.6, "lost": 0})
    rec.log("fault", {"fault": "link lost (no STATE for 56 ms)"})
    rec.action("STOP: STOP pressed by Alice", 7)
    rec.log("overlay", {"name": "path", "points": [[0, 0, 0], [0.1, 0.2, 0]],
                        "color": (255, 0, 255)}, 7)
    rec.log("telemetry", {"p99_ms": np.float64(1.5), "lost": float("nan")})
    rec.stop()
    loaded = load_recording(path, model)
    return path, qs, [float(t) for t in loaded.times]


def test_independent_reader_sees_typed_channels_counts_and_monotonic_times(tmp_path) -> None:
    path, qs, _ = record_session(tmp_path)
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        f.seek(0)
        messages = [(s, c, m) for s, c, m in make_reader(f).iter_messages(log_time_order=False)]
    assert meta["softarm.recording"]["robot"] == "soft-arm"
    assert meta["softarm.recording"]["by"] == "Alice"
    topics = {ch.topic: summary.schemas[ch.schema_id] for ch in summary.channels.values()}
    assert {t: s.name for t, s in topics.items()} == WELL_KNOWN
    assert all(s.encoding == "jsonschema" for s in topics.values())
    assert all(ch.message_encoding == "json" for ch in summary.channels.values())
    counts = {summary.channels[cid].topic: n
              for cid, n in summary.statistics.channel_message_counts.items()}
    assert counts["/arm/configuration"] == counts["/arm/tip"] == counts["/arm/scene"] == 5
    assert counts["/control/loop_timing"] == 5 and counts["/operator/actions"] == 2
    assert counts["/events"] == 4  # 2 actions, the phase change, the fault
    stamps = [m.log_time for _, _, m in messages]
    assert stamps == sorted(stamps) and len(stamps) == summary.statistics.message_count
    start = int(meta["softarm.recording"]["start_ns"])
    assert start <= stamps[0] and stamps[-1] - start < 5e9  # the console's clock in ns
    assert abs(start - time.time_ns()) < 60e9
    for schema, channel, message in messages:
        body = json.loads(message.data)
        check(body, json.loads(schema.data), channel.topic)
        if "timestamp" in body:
            ts = body["timestamp"]
            assert ts["sec"] * 1_000_000_000 + ts["nsec"] == message.log_time
    configs = [json.loads(m.data) for _, c, m in messages if c.topic == "/arm/configuration"]
    assert [[s["kappa"] for s in c["measured"]] for c in configs] == [q.tolist() for q in qs]
    assert [[s["kappa"] for s in c["commanded"]] for c in configs] == \
        [(q + 0.5).tolist() for q in qs]
    logs = [json.loads(m.data) for _, c, m in messages if c.topic == "/events"]
    assert [(lg["level"], lg["name"]) for lg in logs] == [(2, "Alice"), (2, "server"),
                                                         (4, "server"), (3, "Alice")]
    telemetry = [json.loads(m.data) for _, c, m in messages if c.topic == "/console/telemetry"]
    # free-form data is JSON text (Lichtblick types no open object); the NaN is left out, not null
    assert json.loads(telemetry[0]["data"]) == {"p99_ms": 1.5}


def test_tip_pose_and_scene_follow_the_closed_form_arc(tmp_path) -> None:
    arm = ArmGeometry(SOFT)
    kappa = 5.0
    q = np.full(6, kappa)
    with McapLog(tmp_path / "arc.mcap", {"robot": "soft-arm"}, 10**18, arm) as log:
        log.record({"kind": "state", "q": q.tolist(), "seq": 1, "source": "jog", "t": 0.5})
    with open(tmp_path / "arc.mcap", "rb") as f:
        msgs = {c.topic: (json.loads(m.data), m.log_time)
                for _, c, m in make_reader(f).iter_messages()}
    length = sum(SOFT.lengths)
    th0 = math.pi / 2
    th = th0 + kappa * length
    expect = [(math.sin(th) - math.sin(th0)) / kappa, (math.cos(th0) - math.cos(th)) / kappa]
    tip, ns = msgs["/arm/tip"]
    assert ns == 10**18 + 500_000_000
    p, o = tip["pose"]["position"], tip["pose"]["orientation"]
    np.testing.assert_allclose([p["x"], p["y"]], expect, atol=1e-9)
    np.testing.assert_allclose([o["z"], o["w"]], [math.sin(th / 2), math.cos(th / 2)], atol=1e-9)
    scene, _ = msgs["/arm/scene"]
    pts = np.array([[v["x"], v["y"]] for v in scene["entities"][0]["lines"][0]["points"]])
    radius = np.hypot(*(pts - pts[0] - np.array([-1.0 / kappa, 0.0])).T)
    np.testing.assert_allclose(radius, 1.0 / kappa, atol=1e-9)  # every point on the arc
    np.testing.assert_allclose(pts[-1], expect, atol=1e-9)
    assert scene["deletions"] == [{"timestamp": {"sec": 10**9, "nsec": 500_000_000},
                                  "type": 1, "id": ""}]
    for m in Rotation.random(20, random_state=3).as_matrix():
        qa, qb = quaternion(m), Rotation.from_matrix(m).as_quat()
        assert min(np.abs(qa - qb).max(), np.abs(qa + qb).max()) < 1e-9


def test_replay_of_an_mcap_shows_the_recorded_configuration_at_three_times(tmp_path) -> None:
    path, qs, times = record_session(tmp_path)
    rec = load_recording(path, model_for(SOFT))
    assert rec.name == path.name and len(rec.times) == 5
    for i in (1, 3, 4):
        np.testing.assert_allclose(rec.q_at(times[i]), qs[i])
        np.testing.assert_allclose(rec.q_at(times[i] - 1e-4), qs[i - 1])
    kinds = [(e.kind, e.who) for e in rec.events]
    assert kinds == [("action", "Alice"), ("objects", "Alice"), ("plan", "Alice"),
                     *[("timing", "server")] * 5, ("phase", "server"), ("link", "server"),
                     ("fault", "server"), ("action", "Alice"), ("overlay", "Alice"),
                     ("telemetry", "server")]
    assert rec.events[0].text == "took control"
    assert rec.overlays_until(rec.duration + 1)["path"]["points"] == [[0, 0, 0], [0.1, 0.2, 0]]
    with pytest.raises(ValueError, match="recorded on 'soft-arm'"):
        load_recording(path, model_for(EXT))
    broken = tmp_path / "recordings" / "broken.mcap"
    broken.write_bytes(path.read_bytes()[:200])
    with pytest.raises(ValueError, match="broken.mcap"):
        load_recording(broken, model_for(SOFT))


def test_an_old_jsonl_recording_converts_and_replays_the_same(tmp_path, capsys) -> None:
    model = model_for(EXT)
    store = StateStore(model)
    rec = Recorder(DataDir(tmp_path), model, suffix=SUFFIX)
    old = rec.start("old")
    assert old.name.endswith(".jsonl.gz")
    qs = [np.array([[0.01 * k, 0.0, 0.02], [0.0, -0.01 * k, 0.01]]) for k in range(4)]
    for q in qs:
        rec.on_state(store.request(q, "jog"))
        time.sleep(0.01)
    rec.action("took control", None)
    rec.log("overlay", {"name": "plan", "points": [[0, 0, 0], [0.1, 0.1, 0.1]]})
    rec.stop()
    new = tmp_path / "recordings" / "new.mcap"
    assert labdata_cli.main(["convert", str(old), str(new)]) == 0
    assert capsys.readouterr().err == ""  # not a terminal: no progress bar
    a, b = load_recording(old, model), load_recording(new, model)
    np.testing.assert_allclose(b.qs, a.qs, atol=1e-12)
    np.testing.assert_allclose(b.times, a.times, atol=1e-6)
    assert [(e.kind, e.who, e.text) for e in b.events] == [(e.kind, e.who, e.text)
                                                            for e in a.events]
    assert labdata_cli.main(["info", str(new)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["channels"]["/arm/configuration"] == {"schema": "softarm.Configuration",
                                                      "messages": 4}
    assert info["channels"]["/arm/scene"]["schema"] == "foxglove.SceneUpdate"
    assert labdata_cli.main(["convert", str(old), str(new)]) == 2  # never overwrites
    assert "exists" in capsys.readouterr().err
    junk = tmp_path / "junk.jsonl.gz"
    junk.write_bytes(b"not gzip")
    assert labdata_cli.main(["convert", str(junk), str(tmp_path / "junk.mcap")]) == 2
    assert not (tmp_path / "junk.mcap").exists()


def test_a_ten_minute_session_stays_under_50_mb(tmp_path) -> None:
    """One minute at the console's 30 Hz render rate, with loop timing at 20 Hz and an action
    every second, scaled by ten (chunks compress independently, so size is linear in time)."""
    arm = ArmGeometry(SOFT)
    path = tmp_path / "minute.mcap"
    rng = np.random.default_rng(0)
    with McapLog(path, {"robot": "soft-arm"}, time.time_ns(), arm) as log:
        for i in range(60 * 30):
            t = i / 30
            q = 12.0 * np.sin(0.4 * t + np.arange(6)) + rng.normal(0, 0.05, 6)
            log.record({"kind": "state", "q": q.tolist(), "seq": i, "source": "hardware",
                        "command": (q + 0.1).tolist(), "t": t})
            if i % 3 != 2:
                log.record({"kind": "timing", "t": t, "data": {
                    "tick": i * 3, "period_ms": 10 + rng.normal(0, 0.05),
                    "work_ms": 0.4 + rng.normal(0, 0.02), "overruns": 0}})
            if i % 30 == 0:
                log.record({"kind": "action", "what": "jog", "who": "Alice", "client": 3,
                            "t": t})
    assert 10 * path.stat().st_size < 50e6


def _enum(cls: Any, value: int) -> Any:
    return next(getattr(cls, n) for n in dir(cls)
                if not n.startswith("_") and n not in ("name", "value")
                and getattr(cls, n).value == value)


def to_sdk(kind: str, value: Any) -> Any:
    """Build foxglove-sdk's own typed message ``kind`` from our JSON (field names must match)."""
    import foxglove.messages as fm

    nested = {
        "SceneUpdate": {"deletions": "SceneEntityDeletion", "entities": "SceneEntity"},
        "SceneEntity": {"timestamp": "Timestamp", "lifetime": "Duration",
                        "metadata": "KeyValuePair", "spheres": "SpherePrimitive",
                        "cylinders": "CylinderPrimitive", "lines": "LinePrimitive",
                        "texts": "TextPrimitive"},
        "SceneEntityDeletion": {"timestamp": "Timestamp"},
        "LinePrimitive": {"pose": "Pose", "points": "Point3", "color": "Color",
                          "colors": "Color"},
        "CylinderPrimitive": {"pose": "Pose", "size": "Vector3", "color": "Color"},
        "SpherePrimitive": {"pose": "Pose", "size": "Vector3", "color": "Color"},
        "Pose": {"position": "Vector3", "orientation": "Quaternion"},
        "PoseInFrame": {"timestamp": "Timestamp", "pose": "Pose"},
        "Log": {"timestamp": "Timestamp"}}
    enums = {("SceneEntityDeletion", "type"): fm.SceneEntityDeletionType,
             ("LinePrimitive", "type"): fm.LinePrimitiveLineType, ("Log", "level"): fm.LogLevel}
    fields = {}
    for key, v in value.items():
        sub = nested.get(kind, {}).get(key)
        if (kind, key) in enums:
            v = _enum(enums[(kind, key)], v)
        elif sub is not None:
            v = [to_sdk(sub, x) for x in v] if isinstance(v, list) else to_sdk(sub, v)
        elif key in ("arrows", "cubes", "triangles", "models"):
            assert v == []
            continue
        fields[key] = v
    return getattr(fm, kind)(**fields)


def test_well_known_messages_build_as_the_foxglove_sdk_types(tmp_path) -> None:
    """Every foxglove.* message in a recording constructs (and encodes) as foxglove-sdk's typed
    message of that name: the field names and enum values are Foxglove's."""
    path, _, _ = record_session(tmp_path)
    seen = set()
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            if not schema.name.startswith("foxglove."):
                continue
            typed = to_sdk(schema.name.removeprefix("foxglove."), json.loads(message.data))
            assert len(typed.encode()) > 0
            seen.add(schema.name)
    assert seen == {"foxglove.SceneUpdate", "foxglove.PoseInFrame", "foxglove.Log"}


def test_an_mcap_past_the_replay_budget_is_refused_before_its_messages_are_read(tmp_path) -> None:
    """The summary's uncompressed size and message count (read by the independent ``mcap``
    reader here) decide before any message is decompressed; a file within the budget loads."""
    from mcap.reader import make_reader

    from console.recording.recorder import ReadBudget
    from console.recording.mcap_format import load_mcap

    path, _, _ = record_session(tmp_path)
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None
    count = summary.statistics.message_count
    raw = sum(ci.uncompressed_size for ci in summary.chunk_indexes)
    model = model_for(SOFT)
    assert len(load_mcap(path, model, ReadBudget(max_bytes=raw, max_records=count)).times) == 5
    with pytest.raises(ValueError, match=f"more than {count - 1:,} records"):
        load_mcap(path, model, ReadBudget(max_records=count - 1))
    with pytest.raises(ValueError, match="uncompressed"):
        load_mcap(path, model, ReadBudget(max_bytes=raw - 1))
