"""Every lab channel opens in Lichtblick, and its messages match its schema.

Three independent references: Lichtblick's own JSON-schema parser rules
(``tests/lichtblick_schema.py``, ported from its ``parseJsonSchema.ts``), the protobuf definitions
foxglove-sdk ships for Foxglove's well-known messages (``tests/foxglove_proto.py``), and the
``jsonschema`` package validating every message the console writes (live and in an MCAP file read
back with the ``mcap`` package). Messages carry no ``null`` (Lichtblick's datatypes have no
nullable fields): a missing value or a NaN is omitted.
"""

from __future__ import annotations

import io
import json
import math
from typing import Any

import pytest
from mcap.reader import make_reader

from core.labdata import schemas as S
from core.labdata.channels import (CHANNELS, TICK_CHANNELS, ArmGeometry, ChannelSpec,
                                    messages_for, record_from_message, robot_description,
                                    spec_for)
from core.labdata.mcap_file import McapLog
from core.robots import load
from tests.foxglove_proto import Field, messages as proto_messages
from tests.lichtblick_schema import Unsupported, parse_json_schema

SOFT = load("soft-arm")
NS = 1_700_000_000_123_456_789
ALL_SPECS: tuple[ChannelSpec, ...] = CHANNELS + TICK_CHANNELS + (spec_for("/console/anything"),)


def test_the_port_refuses_what_lichtblicks_parser_refuses() -> None:
    def obj(**props: Any) -> dict[str, Any]:
        return {"type": "object", "properties": props}

    for bad, words in [
        (obj(x={"type": ["number", "null"]}), "Unsupported type ['number', 'null'] for x"),
        (obj(x={"type": "null"}), "Unsupported type 'null' for x"),
        (obj(data={}), "Unsupported type None for data"),
        (obj(o={"type": "object"}), "has no properties"),
        (obj(a={"type": "array", "items": {"type": "object"}}), "has no properties"),
        (obj(a={"type": "array", "items": {"type": "array", "items": {"type": "number"}}}),
         "Unsupported type 'array' for array item a"),
        (obj(e={"oneOf": [{"const": "a"}]}), "oneOf alternatives must have number values"),
        (obj(s={"type": "string", "contentEncoding": "hex"}), "Unsupported contentEncoding"),
        ({"type": "array"}, 'Expected "type": "object"'),
    ]:
        with pytest.raises(Unsupported, match=words.replace("[", r"\[").replace("]", r"\]")):
            parse_json_schema(bad, "T")
    types = parse_json_schema(obj(e={"oneOf": [{"title": "A", "const": 0}]},
                                  b={"type": "string", "contentEncoding": "base64"},
                                  n=obj(x={"type": "integer"})), "T")
    assert types["T"][-2:] == [{"name": "b", "type": "uint8", "isArray": True},
                               {"name": "n", "type": "T.n", "isComplex": True}]
    assert types["T.n"] == [{"name": "x", "type": "float64"}]


@pytest.mark.parametrize("spec", ALL_SPECS, ids=lambda s: s.topic)
def test_every_channel_schema_opens_in_lichtblick(spec: ChannelSpec) -> None:
    types = parse_json_schema(spec.schema, spec.schema_name)
    assert types[spec.schema_name]  # at least one field Lichtblick can show


def _check_against_proto(node: dict[str, Any], name: str, msgs: dict[str, list[Field]],
                         enums: dict[str, dict[str, int]], where: str) -> None:
    assert node.get("type") == "object", where
    fields = msgs[name]
    assert list(node["properties"]) == [f.name for f in fields], where
    for f in fields:
        prop = node["properties"][f.name]
        at = f"{where}.{f.name}"
        if f.repeated:
            assert prop["type"] == "array", at
            prop = prop["items"]
        if f.ref in ("google.protobuf.Timestamp", "google.protobuf.Duration"):
            # Foxglove's JSON schemas write time and duration as {sec, nsec}.
            assert prop["type"] == "object" and list(prop["properties"]) == ["sec", "nsec"], at
            assert all(p["type"] == "integer" for p in prop["properties"].values()), at
        elif f.enum:
            assert f.ref is not None
            assert {a["title"]: a["const"] for a in prop["oneOf"]} == enums[f.ref], at
        elif f.ref is not None:
            assert prop.get("title") == f.ref, at
            _check_against_proto(prop, f.ref, msgs, enums, at)
        elif f.scalar == "bytes":
            assert prop == {"type": "string", "contentEncoding": "base64"}, at
        else:
            assert prop["type"] == f.scalar, at


@pytest.mark.parametrize("schema", [S.SCENE_UPDATE, S.POSE_IN_FRAME, S.LOG],
                         ids=lambda s: s["title"])
def test_foxglove_schemas_are_foxglove_sdks_own_definitions(schema: dict[str, Any]) -> None:
    """Every field of the SDK's protobuf definition, with its type, nesting and enum values."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        import foxglove.messages as fm

    short = schema["title"].removeprefix("foxglove.")
    proto = getattr(fm, short).get_schema()
    assert proto.name == schema["title"] and proto.encoding == "protobuf"
    msgs, enums = proto_messages(proto.data)
    _check_against_proto(schema, schema["title"], msgs, enums, short)


def _records() -> list[dict[str, Any]]:
    """One console record of every kind, with the values that used to be written as null."""
    return [
        {"kind": "state", "q": [1.0, -2.0, 3.0, 0.5, 0.0, 2.0], "seq": 4, "source": "jog",
         "command": [1.0, -2.0, 3.0, 0.5, 0.0, 2.5]},
        {"kind": "action", "what": "added object 'cup'", "who": "alice", "client": 3,
         "x_mm": 120.0},
        {"kind": "action", "what": "STOP: test", "who": "server", "client": None},
        {"kind": "objects", "who": "alice", "client": 3, "data": {
            "objects": [{"name": "cup", "x": 0.1, "y": 0.2, "r": 0.02}], "selected": None,
            "obstacles": [{"name": "post", "x": 0.3, "y": 0.0, "r": 0.03}],
            "clearance": 0.01}},
        {"kind": "plan", "data": {"refusal": "out of reach", "circles": [], "waypoints": []}},
        {"kind": "plan", "data": {"refusal": None, "center": [0.1, 0.2], "radius": 0.05,
                                  "circles": [{"x": 0.1, "y": 0.2, "r": 0.05}],
                                  "waypoints": [{"kappa": [1.0] * 6, "palm": [0.1, 0.2, 0.3]}],
                                  "total_ms": 12.5}},
        {"kind": "phase", "data": {"phase": "idle", "reason": None, "armed": False,
                                   "tracking_ok": True, "gripper_closed": False, "waypoint": 0,
                                   "n_waypoints": 0, "replans": 0, "loop_t": 1.5}},
        {"kind": "timing", "data": {"tick": 10, "loop_t": 0.1, "period_ms": 10.0,
                                    "work_ms": float("nan"), "overruns": 0}},
        {"kind": "link", "data": {"device": "soft", "state": "open", "port": "/dev/pts/3",
                                  "armed": False, "rtt_ms_p50": None,
                                  "rtt_ms_p99": float("nan"), "sent": 0, "received": 0,
                                  "lost": 0, "crc_errors": 0}},
        {"kind": "fault", "data": {"fault": "lost link"}},
        {"kind": "overlay", "data": {"name": "path", "points": [[0, 0, 0], [0.1, 0, 0]],
                                     "color": [255, 0, 0]}},
        {"kind": "boxes", "data": {"boxes": [{"name": "b", "centre": [0.1, 0.1, 0.1],
                                              "size": [0.1, 0.1, 0.1]}],
                                   "clearance": 0.01, "note": None}},
        {"kind": "robot", "data": robot_description(load("soft-arm"))},
        {"kind": "telemetry", "client": "abc", "data": {"a": [1, 2], "b": None}},
    ]


def _nulls(value: Any, where: str = "") -> list[str]:
    if value is None:
        return [where or "/"]
    if isinstance(value, float) and not math.isfinite(value):
        return [where]
    if isinstance(value, dict):
        return [p for k, v in value.items() for p in _nulls(v, f"{where}.{k}")]
    if isinstance(value, list):
        return [p for i, v in enumerate(value) for p in _nulls(v, f"{where}[{i}]")]
    return []


def test_messages_hold_no_null_and_read_back_as_the_records() -> None:
    arm = ArmGeometry(SOFT)
    seen: set[str] = set()
    for rec in _records():
        for topic, msg in messages_for(rec, NS, arm):
            seen.add(topic)
            text = json.dumps(msg, allow_nan=False)  # no NaN either
            assert _nulls(json.loads(text)) == [], (topic, msg)
    assert {s.topic for s in CHANNELS} <= seen | {"/arm/tip"}
    link = dict(messages_for(_records()[8], NS, arm))["/link/health"]
    assert "rtt_ms_p50" not in link and "rtt_ms_p99" not in link and link["sent"] == 0
    assert "work_ms" not in dict(messages_for(_records()[7], NS, arm))["/control/loop_timing"]
    action = dict(messages_for(_records()[1], NS, arm))["/operator/actions"]
    assert action["client"] == "3" and json.loads(action["details"]) == {"x_mm": 120.0}
    assert record_from_message("/operator/actions", action) == {
        "kind": "action", "what": "added object 'cup'", "who": "alice", "client": "3",
        "x_mm": 120.0}
    server = dict(messages_for(_records()[2], NS, arm))["/operator/actions"]
    assert "client" not in server and server["who"] == "server"
    other = dict(messages_for(_records()[-1], NS, arm))["/console/telemetry"]
    assert record_from_message("/console/telemetry", other)["data"] == {"a": [1, 2]}
    # files written before (details and data as objects) still read back
    assert record_from_message("/operator/actions", {"what": "w", "who": "x", "client": 1,
                                                     "details": {"k": 1}})["k"] == 1
    assert record_from_message("/console/x", {"kind": "x", "data": {"k": 1}})["data"] == \
        {"k": 1}


def test_recorded_messages_validate_against_their_embedded_schemas() -> None:
    jsonschema = pytest.importorskip("jsonschema")
    buf = io.BytesIO()
    with McapLog(buf, {"robot": "soft-arm", "robot_kind": "planar", "shape": [6]}, NS,
                 ArmGeometry(SOFT)) as log:
        for i, rec in enumerate(_records()):
            log.record({**rec, "ns": NS + i})
    buf.seek(0)
    topics = set()
    for schema, channel, message in make_reader(buf).iter_messages():
        assert schema is not None and schema.encoding == "jsonschema"
        body = json.loads(message.data)
        parsed = json.loads(schema.data)
        parse_json_schema(parsed, schema.name)  # what the file embeds opens in Lichtblick
        jsonschema.validate(body, parsed)
        assert _nulls(body) == [], channel.topic
        topics.add(channel.topic)
    assert {"/objects", "/plan", "/control/phase", "/link/health", "/operator/actions",
            "/scene/objects", "/scene/plan", "/scene/boxes", "/console/telemetry"} <= topics
