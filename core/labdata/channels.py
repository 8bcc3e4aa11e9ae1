"""The lab channels and the pure mapping from console records to channel messages (and back).

A console record is a dict with ``kind`` and ``t`` (s since the recording started), as
``console.recording.recorder.Recorder`` builds it; :func:`messages_for` turns one into ``(topic, message)``
pairs, :func:`record_from_message` turns a message of a record-carrying channel back into the
record (``/arm/configuration`` -> ``state``, ``/operator/actions`` -> ``action``, ``/objects`` ->
``objects`` ...). Derived channels (the 3D scene, tip pose, ``foxglove.Log``) are for the lab
tools and are not read back.

Record kinds with a typed channel: ``state`` (``q``, ``seq``, ``source``, optional ``command``),
``action`` (``what``, ``who``, ``client``, extra details), and for ``log(kind, data)``:
``objects``, ``plan``, ``phase``, ``timing``, ``link``, ``fault``, ``robot`` (the robot file:
:func:`robot_description`) and ``overlay``; any other kind
goes to ``/console/<kind>`` as a ``softarm.Record`` (``boxes``, the extensible arm's box
obstacles, also draws them as cubes on ``/scene/boxes``).
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
from pathlib import Path
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from core.kinematics import delta as dk
from core.kinematics import planar as pk
from core.labdata import schemas as S
from core.robots import ExtensibleArm, Robot, SoftArm

Array = npt.NDArray[np.float64]
FRAME = "world"
NS = 1_000_000_000


@dataclasses.dataclass(frozen=True)
class ChannelSpec:
    """One channel: topic, schema name (the JSON schema's title) and JSON schema."""

    topic: str
    schema: dict[str, Any]

    @property
    def schema_name(self) -> str:
        return str(self.schema["title"])


CONFIGURATION = ChannelSpec("/arm/configuration", S.CONFIGURATION)
TIP = ChannelSpec("/arm/tip", S.POSE_IN_FRAME)
ARM_SCENE = ChannelSpec("/arm/scene", S.SCENE_UPDATE)
OBJECTS = ChannelSpec("/objects", S.OBJECTS)
OBJECT_SCENE = ChannelSpec("/scene/objects", S.SCENE_UPDATE)
PLAN = ChannelSpec("/plan", S.PLAN)
PLAN_SCENE = ChannelSpec("/scene/plan", S.SCENE_UPDATE)
OVERLAY_SCENE = ChannelSpec("/scene/overlays", S.SCENE_UPDATE)
BOX_SCENE = ChannelSpec("/scene/boxes", S.SCENE_UPDATE)  # the extensible arm's box obstacles
PHASE = ChannelSpec("/control/phase", S.PHASE)
TIMING = ChannelSpec("/control/loop_timing", S.TIMING)
LINK = ChannelSpec("/link/health", S.LINK)
ACTIONS = ChannelSpec("/operator/actions", S.ACTION)
FAULTS = ChannelSpec("/faults", S.FAULT)
EVENTS = ChannelSpec("/events", S.LOG)
ROBOT_DESCRIPTION = ChannelSpec("/robot/description", S.ROBOT_DESCRIPTION)
#: Every 100 Hz loop tick (``core.labdata.ticks``): written by recordings, not streamed live.
SOFT_ARM_TICKS = ChannelSpec("/control/ticks", S.SOFT_ARM_TICK)
EXTENSIBLE_TICKS = ChannelSpec("/control/extensible_ticks", S.EXTENSIBLE_TICK)
TICK_CHANNELS: tuple[ChannelSpec, ...] = (SOFT_ARM_TICKS, EXTENSIBLE_TICKS)

#: Every fixed channel (``/console/<kind>`` channels are made on demand with :func:`spec_for`).
CHANNELS: tuple[ChannelSpec, ...] = (CONFIGURATION, TIP, ARM_SCENE, OBJECTS, OBJECT_SCENE, PLAN,
                                     PLAN_SCENE, OVERLAY_SCENE, BOX_SCENE, PHASE, TIMING, LINK,
                                     ACTIONS, FAULTS, EVENTS, ROBOT_DESCRIPTION)
#: ``log(kind, data)`` kinds with their own typed channel (data fields are the message's fields).
TYPED_KINDS: dict[str, ChannelSpec] = {"objects": OBJECTS, "plan": PLAN, "phase": PHASE,
                                       "timing": TIMING, "link": LINK, "fault": FAULTS,
                                       "robot": ROBOT_DESCRIPTION}
#: Record kinds that mark the replay timeline (phase changes, faults, STOP, operator actions).
MARKER_KINDS = ("action", "phase", "fault")
#: Record kinds that carry state (the newest one is what is true now), not events: a recording
#: starts with the newest of each and a live viewer gets them when it subscribes (latched).
LATCHED_KINDS = ("robot", "state", "objects", "plan", "phase", "link", "timing", "boxes",
                 "overlay")
#: Channels of things that happened: never latched (a late viewer must not see a STOP again).
EVENT_TOPICS = (EVENTS.topic, ACTIONS.topic, FAULTS.topic)
_META = ("timestamp", "who", "client")
_KIND_RE = re.compile(r"[^A-Za-z0-9_]+")

LOG_INFO, LOG_WARNING, LOG_ERROR = 2, 3, 4


def spec_for(topic: str) -> ChannelSpec:
    """The channel of ``topic`` (a fixed one, or a ``/console/<kind>`` record channel)."""
    for spec in CHANNELS + TICK_CHANNELS:
        if spec.topic == topic:
            return spec
    if topic.startswith("/console/"):
        return ChannelSpec(topic, S.RECORD)
    raise KeyError(f"no lab channel {topic!r}")


def robot_description(robot: Robot) -> dict[str, str]:
    """The ``robot`` record's data: the robot file the console runs (name, kind, path and its
    text, which ``core.robots.parse`` reads back), logged once at start and latched."""
    return {"name": robot.name, "kind": robot.kind, "file": str(robot.source),
            "toml": Path(robot.source).read_text(encoding="utf-8")}


def latch_key(rec: dict[str, Any]) -> str | None:
    """The key under which record ``rec`` is the current state (its kind; an overlay's kind and
    name, since each named overlay stands alone), or None for an event (an action, a fault...)."""
    kind = str(rec.get("kind", ""))
    if kind not in LATCHED_KINDS:
        return None
    if kind == "overlay":
        data = rec.get("data")
        return f"overlay/{data.get('name', 'overlay') if isinstance(data, dict) else 'overlay'}"
    return kind


def stamp(ns: int) -> dict[str, int]:
    """Foxglove ``time`` of ``ns`` nanoseconds."""
    return {"sec": int(ns // NS), "nsec": int(ns % NS)}


_OMIT = object()  # json_safe: a value left out (None, NaN, a list holding one)


def _clean(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return _clean(value.tolist())
    if isinstance(value, np.generic):
        return _clean(value.item())
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return _clean(dataclasses.asdict(value))
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return _OMIT
    if isinstance(value, dict):
        out = {}
        for k, v in value.items():
            c = _clean(v)
            if c is not _OMIT:
                out[str(k)] = c
        return out
    if isinstance(value, (list, tuple, set)):
        items = [_clean(v) for v in value]
        return _OMIT if any(c is _OMIT for c in items) else items
    if isinstance(value, (bool, int, float, str)):
        return value
    return repr(value)


def json_safe(value: Any) -> Any:
    """``value`` made JSON-able for a typed channel (recursively): numpy arrays and scalars,
    tuples and dataclasses become JSON values, and what has no value is left out rather than
    written as ``null`` (Lichtblick's schemas have no nullable fields): a ``None`` or non-finite
    number (NaN: a lost measurement; inf) drops its field, and a list holding one drops the whole
    list's field (a list with a hole would misalign its elements). None if ``value`` itself has
    no value."""
    c = _clean(value)
    return None if c is _OMIT else c


def _client(rec: dict[str, Any]) -> dict[str, str]:
    """The ``client`` field of a message (the viser client id as text), empty for the server."""
    cid = rec.get("client")
    return {} if cid is None else {"client": str(cid)}


class ArmGeometry:
    """What the scene and tip channels need from a robot: backbone points and the tip pose."""

    def __init__(self, robot: Robot, samples_per_segment: int = 8) -> None:
        self.robot = robot
        self.samples = samples_per_segment
        self.kind: Literal["planar", "delta"] = "planar" if isinstance(robot, SoftArm) else "delta"
        self.shape = ((robot.n_segments,) if self.kind == "planar"
                      else (robot.n_segments, 3))

    def segments(self, q: npt.ArrayLike) -> list[dict[str, float]]:
        """``q`` as per-segment objects: ``{kappa}`` or ``{dx, dy, dL}``."""
        arr = np.asarray(q, dtype=float)
        if self.kind == "planar":
            return [{"kappa": float(k)} for k in arr.reshape(-1)]
        return [{"dx": float(a), "dy": float(b), "dL": float(c)} for a, b, c in arr.reshape(-1, 3)]

    def q_of(self, segments: list[dict[str, Any]]) -> Array:
        """Inverse of :meth:`segments` (raises ValueError for a wrong shape)."""
        keys = ("kappa",) if self.kind == "planar" else ("dx", "dy", "dL")
        try:
            q = np.array([[float(s[k]) for k in keys] for s in segments], dtype=float)
        except (KeyError, TypeError, ValueError):
            raise ValueError(f"segments are not {'/'.join(keys)} objects") from None
        q = q.reshape(-1) if self.kind == "planar" else q
        if q.shape != self.shape:
            raise ValueError(f"configuration has shape {q.shape}, expected {self.shape}")
        return q

    def backbone(self, q: npt.ArrayLike) -> Array:
        """Backbone points (k, 3) in the world frame (planar arm: at its tube's height)."""
        return self.shape_and_tip(q)[0]

    def tip(self, q: npt.ArrayLike) -> tuple[Array, Array]:
        """Tip position (3,) and orientation quaternion (x, y, z, w)."""
        _, pos, quat = self.shape_and_tip(q)
        return pos, quat

    def shape_and_tip(self, q: npt.ArrayLike) -> tuple[Array, Array, Array]:
        """Backbone points (k, 3), tip position (3,) and tip quaternion (x, y, z, w) at once."""
        q = np.asarray(q, dtype=float)
        r = self.robot
        if isinstance(r, SoftArm):
            pts = pk.sample_backbone(q, r.lengths, self.samples, r.base_pose)
            x, y, th = pts[-1]
            backbone = np.column_stack([pts[:, :2], np.full(len(pts), r.half_width)])
            return (backbone, np.array([x, y, r.half_width]),
                    np.array([0.0, 0.0, math.sin(th / 2), math.cos(th / 2)]))
        assert isinstance(r, ExtensibleArm)
        ends = dk.forward_kinematics(q, r.L0, r.d)
        s = np.linspace(0.0, 1.0, self.samples + 1)
        sub = np.empty((len(q), len(s), 3))
        sub[..., :2] = q[:, None, :2] * s[None, :, None]
        sub[..., 2] = (r.L0 + q[:, 2])[:, None] * s[None, :] - r.L0
        frames = np.einsum("nij,nsjk->nsik", ends[:-1], dk.segment_transform(sub, r.L0, r.d))
        pts = frames[..., :3, 3]
        backbone = np.concatenate([pts[0, :1], pts[:, 1:].reshape(-1, 3)])
        return backbone, ends[-1, :3, 3].copy(), quaternion(ends[-1, :3, :3])


def quaternion(m: Array) -> Array:
    """Unit quaternion (x, y, z, w) of rotation matrix ``m`` (Shepperd's method)."""
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = 2.0 * math.sqrt(tr + 1.0)
        out = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, s / 4]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        out = [s / 4, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        out = [(m[0, 1] + m[1, 0]) / s, s / 4, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        out = [(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, s / 4, (m[1, 0] - m[0, 1]) / s]
    quat = np.array(out, dtype=float)
    return quat / np.linalg.norm(quat)


def _vec(p: Any) -> dict[str, float]:
    return {"x": float(p[0]), "y": float(p[1]), "z": float(p[2]) if len(p) > 2 else 0.0}


def _pose(position: Any = (0.0, 0.0, 0.0), quat: Any = (0.0, 0.0, 0.0, 1.0)) -> dict[str, Any]:
    return {"position": _vec(position),
            "orientation": {"x": float(quat[0]), "y": float(quat[1]), "z": float(quat[2]),
                            "w": float(quat[3])}}


def _color(rgb: Any, a: float = 1.0) -> dict[str, float]:
    r, g, b = (float(c) / 255.0 for c in tuple(rgb)[:3])
    return {"r": r, "g": g, "b": b, "a": a}


def entity(ns: int, eid: str, **primitives: list[dict[str, Any]]) -> dict[str, Any]:
    """A ``foxglove.SceneEntity`` in the world frame with the given primitive lists."""
    out: dict[str, Any] = {"timestamp": stamp(ns), "frame_id": FRAME, "id": eid,
                           "lifetime": {"sec": 0, "nsec": 0}, "frame_locked": False,
                           "metadata": []}
    for key in ("arrows", "cubes", "spheres", "cylinders", "lines", "triangles", "texts",
                "models"):
        out[key] = primitives.get(key, [])
    return out


def line(points: Any, rgb: Any, thickness: float = 0.006, loop: bool = False) -> dict[str, Any]:
    """A ``foxglove.LinePrimitive`` (strip, or loop) through ``points`` (k, 3)."""
    return {"type": 1 if loop else 0, "pose": _pose(), "thickness": thickness,
            "scale_invariant": False, "points": [_vec(p) for p in points],
            "color": _color(rgb), "colors": [], "indices": []}


def sphere(p: Any, d: float, rgb: Any) -> dict[str, Any]:
    return {"pose": _pose(p), "size": {"x": d, "y": d, "z": d}, "color": _color(rgb)}


def scene_update(ns: int, entities: list[dict[str, Any]], replace: bool = True) -> dict[str, Any]:
    """A ``foxglove.SceneUpdate``; ``replace`` deletes the channel's older entities first."""
    deletions = [{"timestamp": stamp(ns), "type": 1, "id": ""}] if replace else []
    return {"deletions": deletions, "entities": entities}


def log_message(ns: int, level: int, message: str, name: str) -> dict[str, Any]:
    """A ``foxglove.Log`` message."""
    return {"timestamp": stamp(ns), "level": level, "message": message, "name": name,
            "file": "", "line": 0}


ARM_RGB, END_RGB, OBJECT_RGB, PLAN_RGB, WAYPOINT_RGB = ((38, 110, 150), (30, 30, 40),
                                                        (60, 170, 90), (200, 40, 160),
                                                        (235, 130, 30))
BOX_RGB = (225, 150, 40)
OBSTACLE_RGB, RING_RGB = (70, 72, 78), (215, 40, 40)


def _circle(x: float, y: float, r: float, z: float, n: int = 48) -> Array:
    a = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    return np.column_stack([x + r * np.cos(a), y + r * np.sin(a), np.full(n, z)])


def _state_messages(rec: dict[str, Any], ns: int, arm: ArmGeometry) -> list[tuple[str, Any]]:
    q = np.asarray(rec["q"], dtype=float)
    command = rec.get("command")
    config = {"timestamp": stamp(ns), "seq": int(rec.get("seq", 0)),
              "source": str(rec.get("source", "")), "kind": arm.kind,
              "measured": arm.segments(q),
              "commanded": arm.segments(q if command is None else command)}
    pts, pos, quat = arm.shape_and_tip(q)
    ends = pts[::arm.samples]
    body = entity(ns, "arm", lines=[line(pts, ARM_RGB, 0.01)],
                  spheres=[sphere(p, 0.012, END_RGB) for p in ends[1:]])
    return [(CONFIGURATION.topic, config),
            (TIP.topic, {"timestamp": stamp(ns), "frame_id": FRAME, "pose": _pose(pos, quat)}),
            (ARM_SCENE.topic, scene_update(ns, [body]))]


def _action_level(what: str) -> int:
    low = what.lower()
    if "fault" in low:
        return LOG_ERROR
    if low.startswith(("stop", "refused")):
        return LOG_WARNING
    return LOG_INFO


def _scene_for(kind: str, data: dict[str, Any], ns: int,
               arm: ArmGeometry | None) -> list[tuple[str, Any]]:
    z = 0.001
    if kind == "objects":
        cyls = []
        for o in data.get("objects") or []:
            d = 2 * float(o["r"])
            cyls.append({"pose": _pose((o["x"], o["y"], 0.015)),
                         "size": {"x": d, "y": d, "z": 0.03}, "bottom_scale": 1.0,
                         "top_scale": 1.0, "color": _color(OBJECT_RGB, 0.9)})
        entities = [entity(ns, "objects", cylinders=cyls)]
        # Obstacles: dark grey, taller than objects, with a red clearance ring (the entity is
        # always sent, so removing the last obstacle clears it).
        obstacles = data.get("obstacles") or []
        clearance = float(data.get("clearance") or 0.0)
        bodies = [{"pose": _pose((o["x"], o["y"], 0.03)),
                   "size": {"x": 2 * float(o["r"]), "y": 2 * float(o["r"]), "z": 0.06},
                   "bottom_scale": 1.0, "top_scale": 1.0, "color": _color(OBSTACLE_RGB, 1.0)}
                  for o in obstacles]
        rings = [line(_circle(o["x"], o["y"], float(o["r"]) + clearance, z), RING_RGB, 0.003,
                      loop=True) for o in obstacles]
        entities.append(entity(ns, "obstacles", cylinders=bodies, lines=rings))
        return [(OBJECT_SCENE.topic, scene_update(ns, entities))]
    if kind == "plan":
        lines = [line(_circle(c["x"], c["y"], c["r"], z), PLAN_RGB, 0.002, loop=True)
                 for c in data.get("circles") or []]
        points = []
        for w in data.get("waypoints") or []:
            if w.get("palm") is not None:
                points.append((w["palm"][0], w["palm"][1], z))
            elif w.get("point") is not None:
                points.append(tuple(w["point"]))
        if len(points) >= 2:
            lines.append(line(points, WAYPOINT_RGB, 0.003))
        spheres = [sphere(p, 0.008, WAYPOINT_RGB) for p in points]
        return [(PLAN_SCENE.topic, scene_update(ns, [entity(ns, "plan", lines=lines,
                                                            spheres=spheres)]))]
    if kind == "boxes":  # data: core.planning.box_scene.scene_to_dict
        cubes = [{"pose": _pose(b["centre"]), "size": dict(zip("xyz", map(float, b["size"]))),
                  "color": _color(BOX_RGB, 0.4)} for b in data.get("boxes") or []]
        return [(BOX_SCENE.topic, scene_update(ns, [entity(ns, "boxes", cubes=cubes)]))]
    if kind == "overlay":
        pts = np.asarray(data.get("points", ()), dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 2:
            return []
        name = str(data.get("name", "overlay"))
        ent = entity(ns, f"overlay/{name}",
                     lines=[line(pts, data.get("color", PLAN_RGB), 0.004)])
        return [(OVERLAY_SCENE.topic, scene_update(ns, [ent], replace=False))]
    return []


def messages_for(rec: dict[str, Any], ns: int,
                 arm: ArmGeometry | None) -> list[tuple[str, dict[str, Any]]]:
    """The ``(topic, message)`` pairs of console record ``rec`` logged at ``ns`` (epoch ns).

    ``arm`` may be None only when no record is a ``state`` (it raises ValueError then).
    """
    kind = str(rec.get("kind", ""))
    who = str(rec.get("who", "server"))
    client = _client(rec)
    if kind == "state":
        if arm is None:
            raise ValueError("a state record needs the arm geometry")
        return _state_messages(rec, ns, arm)
    if kind == "action":
        what = str(rec.get("what", ""))
        details = json_safe({k: v for k, v in rec.items()
                             if k not in ("kind", "t", "ns", "who", "client", "what")})
        out: list[tuple[str, dict[str, Any]]] = [
            (ACTIONS.topic, {"timestamp": stamp(ns), "what": what, "who": who, **client,
                             "details": json.dumps(details, separators=(",", ":"))}),
            (EVENTS.topic, log_message(ns, _action_level(what), what, who))]
        return out
    data = json_safe(rec.get("data"))
    if kind in TYPED_KINDS and isinstance(data, dict):
        msg = {**data, "timestamp": stamp(ns), "who": who, **client}
        out = [(TYPED_KINDS[kind].topic, msg)]
        if kind == "phase":
            reason = f" ({data['reason']})" if data.get("reason") else ""
            out.append((EVENTS.topic, log_message(ns, LOG_INFO,
                                                  f"phase: {data.get('phase')}{reason}", who)))
        elif kind == "fault":
            out.append((EVENTS.topic, log_message(ns, LOG_ERROR,
                                                  f"fault: {data.get('fault')}", who)))
        return out + _scene_for(kind, data, ns, arm)
    topic = "/console/" + (_KIND_RE.sub("_", kind).strip("_") or "record")
    out = [(topic, {"timestamp": stamp(ns), "kind": kind, "who": who, **client,
                    "data": json.dumps(data, separators=(",", ":"))})]
    if kind in ("overlay", "boxes") and isinstance(data, dict):
        out += _scene_for(kind, data, ns, arm)
    return out


def record_from_message(topic: str, msg: dict[str, Any]) -> dict[str, Any] | None:
    """The console record a message carries (without ``t``), or None for derived channels."""
    if topic == CONFIGURATION.topic:
        return {"kind": "state", "measured": msg.get("measured", []),
                "commanded": msg.get("commanded"), "seq": msg.get("seq", 0),
                "source": msg.get("source", "")}
    if topic == ACTIONS.topic:
        return {"kind": "action", "what": msg.get("what", ""), "who": msg.get("who", ""),
                "client": msg.get("client"), **(_json_object(msg.get("details")) or {})}
    for kind, spec in TYPED_KINDS.items():
        if spec.topic == topic:
            return {"kind": kind, "who": msg.get("who", ""), "client": msg.get("client"),
                    "data": {k: v for k, v in msg.items() if k not in _META}}
    if topic.startswith("/console/"):
        data = msg.get("data")
        return {"kind": str(msg.get("kind", topic.removeprefix("/console/"))),
                "who": msg.get("who", ""), "client": msg.get("client"),
                "data": _json_text(data) if isinstance(data, str) else data}
    return None


def _json_text(text: str) -> Any:
    """JSON text written by :func:`messages_for` (older files held the value itself)."""
    try:
        return json.loads(text)
    except ValueError:
        return text


def _json_object(value: Any) -> dict[str, Any] | None:
    """An action's details: JSON text (an object) now, the object itself in older files."""
    value = _json_text(value) if isinstance(value, str) else value
    return value if isinstance(value, dict) else None
