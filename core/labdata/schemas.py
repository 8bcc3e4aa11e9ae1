"""JSON schemas of the lab channels, so Foxglove/Lichtblick render them and ROS-side tools type them.

Three are Foxglove's well-known schemas in their JSON form (every field of Foxglove's own
definition, with its field names, ``oneOf`` enums and ``time``/``duration`` objects; the
installed foxglove-sdk's protobuf definition of each is the reference that
``tests/core/test_lichtblick_schemas.py`` checks them against), which Foxglove and Lichtblick
recognise by name: ``foxglove.SceneUpdate`` (3D panel), ``foxglove.PoseInFrame`` (3D panel,
plots) and ``foxglove.Log`` (Log panel). The others are the console's own (``softarm.*``), plain JSON objects whose numeric fields plot
directly (e.g. ``/control/loop_timing.work_ms``).

Every schema opens in Lichtblick (its parser, ``parseJsonSchema.ts``, accepts one type per field,
objects with properties, arrays of one typed item): no type unions such as ``["number", "null"]``
and no untyped objects. A field without a value is omitted from the message, never ``null``; a
non-finite number (NaN, a lost measurement) is omitted with its field (see
``core.labdata.channels.json_safe``); free-form data (an action's details, ``softarm.Record``'s
data) is JSON text in a string field.
"""

from __future__ import annotations

from typing import Any

Schema = dict[str, Any]

NUMBER: Schema = {"type": "number"}
INTEGER: Schema = {"type": "integer"}
TEXT: Schema = {"type": "string"}
BOOL: Schema = {"type": "boolean"}
WHO: Schema = {"type": "string", "description": "display name of who did it ('server' if none)"}
CLIENT: Schema = {"type": "string",
                  "description": "viser client id of who did it (omitted for the server)"}

TIME: Schema = {"type": "object", "title": "time",
                "properties": {"sec": {"type": "integer", "minimum": 0},
                               "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}}
DURATION: Schema = {"type": "object", "title": "duration",
                    "properties": {"sec": INTEGER,
                                   "nsec": {"type": "integer", "minimum": 0,
                                            "maximum": 999999999}}}
def _enum(title: str, description: str, values: list[tuple[str, int]]) -> Schema:
    """A Foxglove enum field as its JSON schemas write it: ``oneOf`` titled numeric constants."""
    return {"title": title, "description": description,
            "oneOf": [{"title": name, "const": value} for name, value in values]}


VECTOR3: Schema = {"type": "object", "title": "foxglove.Vector3",
                   "properties": {"x": NUMBER, "y": NUMBER, "z": NUMBER}}
POINT3: Schema = {"type": "object", "title": "foxglove.Point3",
                  "properties": {"x": NUMBER, "y": NUMBER, "z": NUMBER}}
QUATERNION: Schema = {"type": "object", "title": "foxglove.Quaternion",
                      "properties": {"x": NUMBER, "y": NUMBER, "z": NUMBER, "w": NUMBER}}
POSE: Schema = {"type": "object", "title": "foxglove.Pose",
                "properties": {"position": VECTOR3, "orientation": QUATERNION}}
COLOR: Schema = {"type": "object", "title": "foxglove.Color",
                 "properties": {"r": NUMBER, "g": NUMBER, "b": NUMBER, "a": NUMBER}}


def _array(items: Schema) -> Schema:
    return {"type": "array", "items": items}


def _object(title: str, description: str, properties: dict[str, Schema],
            extra: bool = False) -> Schema:
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": title,
            "description": description, "type": "object", "properties": properties,
            "additionalProperties": extra}


LINE_PRIMITIVE: Schema = {
    "type": "object", "title": "foxglove.LinePrimitive",
    "properties": {"type": _enum("foxglove.LineType", "An enumeration indicating how input "
                                 "points should be interpreted to create lines",
                                 [("LINE_STRIP", 0), ("LINE_LOOP", 1), ("LINE_LIST", 2)]),
                   "pose": POSE, "thickness": NUMBER, "scale_invariant": BOOL,
                   "points": _array(POINT3), "color": COLOR, "colors": _array(COLOR),
                   "indices": _array(INTEGER)}}
CYLINDER_PRIMITIVE: Schema = {
    "type": "object", "title": "foxglove.CylinderPrimitive",
    "properties": {"pose": POSE, "size": VECTOR3, "bottom_scale": NUMBER, "top_scale": NUMBER,
                   "color": COLOR}}
SPHERE_PRIMITIVE: Schema = {"type": "object", "title": "foxglove.SpherePrimitive",
                            "properties": {"pose": POSE, "size": VECTOR3, "color": COLOR}}
TEXT_PRIMITIVE: Schema = {
    "type": "object", "title": "foxglove.TextPrimitive",
    "properties": {"pose": POSE, "billboard": BOOL, "font_size": NUMBER,
                   "scale_invariant": BOOL, "color": COLOR, "text": TEXT}}
ARROW_PRIMITIVE: Schema = {
    "type": "object", "title": "foxglove.ArrowPrimitive",
    "properties": {"pose": POSE, "shaft_length": NUMBER, "shaft_diameter": NUMBER,
                   "head_length": NUMBER, "head_diameter": NUMBER, "color": COLOR}}
CUBE_PRIMITIVE: Schema = {"type": "object", "title": "foxglove.CubePrimitive",
                          "properties": {"pose": POSE, "size": VECTOR3, "color": COLOR}}
TRIANGLE_LIST_PRIMITIVE: Schema = {
    "type": "object", "title": "foxglove.TriangleListPrimitive",
    "properties": {"pose": POSE, "points": _array(POINT3), "color": COLOR,
                   "colors": _array(COLOR), "indices": _array(INTEGER)}}
MODEL_PRIMITIVE: Schema = {
    "type": "object", "title": "foxglove.ModelPrimitive",
    "properties": {"pose": POSE, "scale": VECTOR3, "color": COLOR, "override_color": BOOL,
                   "url": TEXT, "media_type": TEXT,
                   "data": {"type": "string", "contentEncoding": "base64"}}}
SCENE_ENTITY: Schema = {
    "type": "object", "title": "foxglove.SceneEntity",
    "properties": {"timestamp": TIME, "frame_id": TEXT, "id": TEXT, "lifetime": DURATION,
                   "frame_locked": BOOL,
                   "metadata": _array({"type": "object", "title": "foxglove.KeyValuePair",
                                       "properties": {"key": TEXT, "value": TEXT}}),
                   "arrows": _array(ARROW_PRIMITIVE), "cubes": _array(CUBE_PRIMITIVE),
                   "spheres": _array(SPHERE_PRIMITIVE), "cylinders": _array(CYLINDER_PRIMITIVE),
                   "lines": _array(LINE_PRIMITIVE),
                   "triangles": _array(TRIANGLE_LIST_PRIMITIVE),
                   "texts": _array(TEXT_PRIMITIVE), "models": _array(MODEL_PRIMITIVE)}}
SCENE_UPDATE: Schema = _object(
    "foxglove.SceneUpdate", "An update to the entities displayed in a 3D scene",
    {"deletions": _array({"type": "object", "title": "foxglove.SceneEntityDeletion",
                          "properties": {"timestamp": TIME,
                                         "type": _enum("foxglove.SceneEntityDeletionType",
                                                       "An enumeration indicating which "
                                                       "entities should match a "
                                                       "SceneEntityDeletion command",
                                                       [("MATCHING_ID", 0), ("ALL", 1)]),
                                         "id": TEXT}}),
     "entities": _array(SCENE_ENTITY)})
POSE_IN_FRAME: Schema = _object(
    "foxglove.PoseInFrame", "A timestamped pose for an object or reference frame in 3D space",
    {"timestamp": TIME, "frame_id": TEXT, "pose": POSE})
LOG: Schema = _object(
    "foxglove.Log", "A log message",
    {"timestamp": TIME,
     "level": _enum("foxglove.LogLevel", "Log level",
                    [("UNKNOWN", 0), ("DEBUG", 1), ("INFO", 2), ("WARNING", 3), ("ERROR", 4),
                     ("FATAL", 5)]),
     "message": TEXT, "name": TEXT, "file": TEXT, "line": {"type": "integer", "minimum": 0}})

SEGMENT: Schema = {
    "type": "object",
    "description": "one segment: planar arm {kappa} (1/m); extensible arm {dx, dy, dL} (m)",
    "properties": {"kappa": NUMBER, "dx": NUMBER, "dy": NUMBER, "dL": NUMBER}}
CONFIGURATION: Schema = _object(
    "softarm.Configuration",
    "Arm configuration per segment: measured (what the console drew: the hardware's measurement "
    "when a device is connected) and commanded (the newest command)",
    {"timestamp": TIME, "seq": INTEGER, "source": TEXT,
     "kind": {"type": "string", "enum": ["planar", "delta"]},
     "measured": _array(SEGMENT), "commanded": _array(SEGMENT)})
OBJECTS: Schema = _object(
    "softarm.Objects", "Objects and obstacles on the table: cylinders, centre x, y and radius r "
    "in m; clearance: the gap (m) grasp plans keep between the arm and every obstacle",
    {"timestamp": TIME, "who": WHO, "client": CLIENT,
     "objects": _array({"type": "object", "properties": {"name": TEXT, "x": NUMBER,
                                                         "y": NUMBER, "r": NUMBER}}),
     "selected": {"type": "string", "description": "the selected object (omitted: none)"},
     "obstacles": _array({"type": "object", "properties": {"name": TEXT, "x": NUMBER,
                                                           "y": NUMBER, "r": NUMBER}}),
     "clearance": NUMBER}, extra=True)
PLAN: Schema = _object(
    "softarm.Plan",
    "A grasp plan (approach circles around the object, waypoints with curvatures and palm poses)"
    " or a path plan (waypoints); lengths in m, angles in rad, curvatures in 1/m",
    {"timestamp": TIME, "who": WHO, "client": CLIENT,
     "refusal": {"type": "string", "description": "why the planner refused (omitted: a plan)"},
     "center": _array(NUMBER), "radius": NUMBER,
     "circles": _array({"type": "object", "properties": {"x": NUMBER, "y": NUMBER,
                                                         "r": NUMBER}}),
     "waypoints": _array({"type": "object",
                          "properties": {"kappa": _array(NUMBER),
                                         "palm": _array(NUMBER), "point": _array(NUMBER)}})},
    extra=True)
PHASE: Schema = _object(
    "softarm.ControlPhase", "The control state machine's phase (Fig. 3) and flags",
    {"timestamp": TIME, "phase": TEXT, "reason": {"type": "string",
                                                  "description": "why (omitted: no reason)"},
     "armed": BOOL,
     "tracking_ok": BOOL, "gripper_closed": BOOL, "waypoint": INTEGER, "n_waypoints": INTEGER,
     "replans": INTEGER, "who": WHO, "client": CLIENT}, extra=True)
TIMING: Schema = _object(
    "softarm.LoopTiming", "Control loop timing in ms (period and work of the last tick, p99 over "
    "the stats window) and counts",
    {"timestamp": TIME, "tick": INTEGER, "period_ms": NUMBER, "work_ms": NUMBER,
     "overruns": INTEGER, "period_error_ms_p99": NUMBER, "work_ms_p99": NUMBER,
     "who": WHO, "client": CLIENT}, extra=True)
LINK: Schema = _object(
    "softarm.LinkHealth", "Serial link health: lifecycle state, armed, round trip (ms), counters",
    {"timestamp": TIME, "device": TEXT, "state": TEXT, "port": TEXT, "armed": BOOL,
     "rtt_ms_p50": {"type": "number", "description": "omitted before any round trip"},
     "rtt_ms_p99": {"type": "number", "description": "omitted before any round trip"},
     "sent": INTEGER, "received": INTEGER, "lost": INTEGER, "crc_errors": INTEGER,
     "who": WHO, "client": CLIENT}, extra=True)
ACTION: Schema = _object(
    "softarm.OperatorAction", "Something a person did or was refused, with who did it",
    {"timestamp": TIME, "what": TEXT, "who": WHO, "client": CLIENT,
     "details": {"type": "string", "contentMediaType": "application/json",
                 "description": "the action's other details as a JSON object (text)"}})
FAULT: Schema = _object(
    "softarm.Fault", "A hardware or control fault that stopped commanding the arm",
    {"timestamp": TIME, "fault": TEXT, "who": WHO, "client": CLIENT}, extra=True)
ROBOT_DESCRIPTION: Schema = _object(
    "softarm.RobotDescription", "The robot file the console runs (its TOML text as loaded), so "
    "a recording or a late viewer knows the arm's geometry and limits",
    {"timestamp": TIME, "name": TEXT, "kind": TEXT, "file": TEXT,
     "toml": {"type": "string", "contentMediaType": "application/toml",
              "description": "the robot file's text (core.robots.parse reads it back)"},
     "who": WHO, "client": CLIENT})
RECORD: Schema = _object(
    "softarm.Record", "Any other console record: its kind and free-form data",
    {"timestamp": TIME, "kind": TEXT, "who": WHO, "client": CLIENT,
     "data": {"type": "string", "contentMediaType": "application/json",
              "description": "the record's data as JSON text"}})

_TICK_COMMON: dict[str, Schema] = {
    "timestamp": TIME,
    "tick": {"type": "integer", "minimum": 1,
             "description": "the loop's tick index since it started (consecutive)"},
    "t_s": {"type": "number", "description": "the loop's own time of this tick (s)"},
    "phase": TEXT, "armed": BOOL,
    "late_ms": {"type": "number", "description": "wake-up after the deadline (ms)"},
    "period_ms": {"type": "number", "description": "since the previous tick started (ms)"},
    "work_ms": NUMBER, "read_ms": NUMBER, "update_ms": NUMBER, "write_ms": NUMBER,
    "missed": {"type": "integer", "minimum": 0,
               "description": "deadlines skipped after this tick (overruns)"}}
_TICK_NOTE = (" Timing fields are omitted where the loop has no real clock (trials on the "
              "simulated clock); a value not known this tick is omitted, never null.")
SOFT_ARM_TICK: Schema = _object(
    "softarm.SoftArmTick",
    "Every tick of the soft arm's 100 Hz loop: curvature target, trajectory reference and "
    "measurement per segment (1/m), the command written to the device (cylinder volume counts, "
    "2N+1 channels), the state machine's phase and the tick's timing (ms)." + _TICK_NOTE,
    {**_TICK_COMMON,
     "kappa_target_1_per_m": _array(NUMBER), "kappa_reference_1_per_m": _array(NUMBER),
     "kappa_measured_1_per_m": _array(NUMBER), "command_counts": _array(NUMBER)})
EXTENSIBLE_TICK: Schema = _object(
    "softarm.ExtensibleTick",
    "Every tick of the extensible arm's 100 Hz loop: motor demand written and encoders read "
    "(counts), measured segment deltas (dx, dy, dL per segment, m), measured tip (x, y, z, m), "
    "the runner's state and the tick's timing (ms)." + _TICK_NOTE,
    {**_TICK_COMMON,
     "demand_counts": _array(INTEGER), "encoder_counts": _array(INTEGER),
     "delta_measured_m": _array(NUMBER), "tip_measured_m": _array(NUMBER)})
