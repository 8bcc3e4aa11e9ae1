"""The console's feeds into lab data: the control pump's views become phase changes (once per
change), loop timing (once per tick), faults (once) and link health (on change); the grasp
session's objects and a real plan become ``objects`` and ``plan`` records whose circles are
Algorithm 1's approach radii around the object, all readable back from the MCAP file."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from mcap.reader import make_reader

from console.core.datadir import DataDir
from console.recording.lab_feed import ControlFeed, feed_grasp
from console.core.model import model_for
from hw_bridge.soft_arm_process import ControlView
from console.core.grasp_state import Outcome, SessionView
from console.recording.recorder import Recorder, load_recording
from console.core.state import StateStore
from console.core.table_scene import TableObject
from core.control.stack import Telemetry
from core.planning.grasp import plan_grasp
from core.robots import load
from hw_bridge.interface import LinkHealth
from hw_bridge.loop import LoopSnapshot, LoopStats

SOFT = load("soft-arm")


def telemetry(t: float, phase: str, armed: bool = True) -> Telemetry:
    z = np.zeros(6)
    return Telemetry(t=t, armed=armed, phase=phase, reason=None, waypoint=0, n_waypoints=3,
                     replans=0, tracking_ok=True, prepressurised=True, kappa_meas=z + 1,
                     kappa_ref=z + 2, kappa_target=z, commands=np.zeros(13),
                     saturated=np.zeros(13, bool), gripper_closed=False, object_xy=None)


def view(tick: int, phase: str, fault: str | None = None, lost: int = 0) -> ControlView:
    snap = LoopSnapshot(tick=tick, t=tick * 0.01, control=telemetry(tick * 0.01, phase),
                        period_ms=10.0 + tick % 3, work_ms=0.5, read_ms=0.1, update_ms=0.3,
                        write_ms=0.1, overruns=tick // 10, fault=fault)
    stats = LoopStats(*([tick] + [0] * 3 + [0.0] * 9))
    link = LinkHealth(state="active", port="/dev/pts/9", fault=fault, armed=True,
                      watchdog_tripped=False, estop=False, rtt_ms_p50=0.3, rtt_ms_p99=0.6,
                      rtt_ms_last=0.3, sent=tick, received=tick, lost=lost, crc_errors=0,
                      bad_frames=0, device_rx_errors=0, state_age_ms=1.0)
    return ControlView(snap, stats, "SCHED_FIFO", None, None, False, None, device="emulator",
                       link=link, fault=fault)


def topics(path: Path) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = {}
    with open(path, "rb") as f:
        for _, ch, m in make_reader(f).iter_messages():
            out.setdefault(ch.topic, []).append(json.loads(m.data))
    return out


def test_control_views_become_phase_timing_fault_and_link_records(tmp_path) -> None:
    model = model_for(SOFT)
    rec = Recorder(DataDir(tmp_path), model)
    path = rec.start("control")
    rec.on_state(StateStore(model).request(np.ones(6), "control"))
    feed = ControlFeed(rec)
    feed.on_view(None)  # the control process is starting: nothing
    views = [view(1, "idle"), view(1, "idle"), view(2, "approach"), view(3, "approach"),
             view(4, "approach", lost=1), view(5, "stopped", fault="link lost"),
             view(6, "stopped", fault="link lost", lost=1)]
    for v in views:
        feed.on_view(v)
    rec.stop()
    got = topics(path)
    assert [p["phase"] for p in got["/control/phase"]] == ["idle", "approach", "stopped"]
    assert [t["tick"] for t in got["/control/loop_timing"]] == [1, 2, 3, 4, 5, 6]
    assert [t["period_ms"] for t in got["/control/loop_timing"]] == [11.0, 12.0, 10.0, 11.0,
                                                                     12.0, 10.0]
    assert [f["fault"] for f in got["/faults"]] == ["link lost"]
    assert [(h["lost"], h.get("fault"), h["device"]) for h in got["/link/health"]] == \
        [(0, None, "emulator"), (1, None, "emulator"), (0, "link lost", "emulator"),
         (1, "link lost", "emulator")]  # on change only (ticks 1-3 alike)
    assert [lg["message"] for lg in got["/events"]] == [
        "phase: idle", "phase: approach", "phase: stopped", "fault: link lost"]
    loaded = load_recording(path, model)
    markers = [e.kind for e in loaded.events if e.kind in ("phase", "fault")]
    assert markers == ["phase", "phase", "phase", "fault"]


def test_grasp_objects_and_a_real_plan_become_records_and_scene(tmp_path) -> None:
    model = model_for(SOFT)
    rec = Recorder(DataDir(tmp_path), model)
    path = rec.start("grasp")
    rec.on_state(StateStore(model).request(np.zeros(6), "init"))
    obj = TableObject("cup", -0.16, 0.28, 0.0165)
    plan = plan_grasp(SOFT, np.zeros(6), (obj.x, obj.y), obj.r)
    sv = SessionView((obj,), "cup", Outcome(obj, plan, None, 1), 0, False, 1.0, False, None)
    feed_grasp(rec, sv, {"objects", "plan"})
    refused = dataclasses.replace(sv, outcome=Outcome(obj, None, "out of reach", 2))
    feed_grasp(rec, refused, {"plan"})
    feed_grasp(rec, sv, {"inspect"})  # nothing changed that is recorded
    rec.stop()
    got = topics(path)
    assert got["/objects"][0]["objects"] == [{"name": "cup", "x": -0.16, "y": 0.28,
                                             "r": 0.0165}]
    first, second = got["/plan"]
    assert [c["r"] for c in first["circles"]] == plan.radii.tolist()
    assert all((c["x"], c["y"]) == (obj.x, obj.y) for c in first["circles"])
    palms = np.array([w["palm"] for w in first["waypoints"]])
    np.testing.assert_allclose(palms, plan.palm_poses)
    # each palm point lies on its approach circle (Algorithm 1)
    np.testing.assert_allclose(np.hypot(palms[:, 0] - obj.x, palms[:, 1] - obj.y), plan.radii,
                               atol=2e-3)
    assert second["refusal"] == "out of reach" and second["circles"] == []
    cyl = got["/scene/objects"][0]["entities"][0]["cylinders"][0]
    assert cyl["size"]["x"] == 2 * obj.r and cyl["pose"]["position"]["x"] == obj.x
    loops = got["/scene/plan"][0]["entities"][0]["lines"]
    assert sum(ln["type"] == 1 for ln in loops) == len(plan.radii)


def test_a_planned_tip_path_becomes_a_plan_record_with_its_waypoints(tmp_path) -> None:
    from core.kinematics import delta as dk
    from core.planning.paths import build_path, plan_path

    ext = load("extensible")
    q0 = np.zeros((ext.n_segments, 3))
    q0[:, 2] = 0.02
    waypoints = build_path("corners", dk.tip_position(ext, q0), 0.02, "xy")
    path = plan_path(ext, waypoints, speed=0.02, start_delta=q0)
    req = SimpleNamespace(kind="corners", plane="xy", size=0.02, speed=0.02)
    model = model_for(ext)
    rec = Recorder(DataDir(tmp_path), model)
    out = rec.start("path")
    rec.on_state(StateStore(model).request(q0, "jog"))
    from console.recording.lab_feed import path_plan_record
    rec.log("plan", path_plan_record(req, waypoints, path))
    rec.stop()
    got = topics(out)
    (plan,) = got["/plan"]
    np.testing.assert_allclose([w["point"] for w in plan["waypoints"]], waypoints)
    assert plan["path"] == "corners" and plan["duration_s"] == path.duration > 0
    strip = [ln for ln in got["/scene/plan"][0]["entities"][0]["lines"] if ln["type"] == 0]
    np.testing.assert_allclose([[p["x"], p["y"], p["z"]] for p in strip[0]["points"]],
                               waypoints)


def test_a_tap_joining_with_the_latched_state_misses_no_record_logged_meanwhile(tmp_path) -> None:
    """``add_tap(fn, latched=True)`` hands ``fn`` the latched records and every later one in one
    step: while another thread logs the table over and over, each of 50 taps that join in the
    middle ends with the newest table (before, the latched records were read apart from joining,
    and a table logged in between reached neither: a late Foxglove viewer saw an empty table)."""
    import threading

    rec = Recorder(DataDir(tmp_path), model_for(load("soft-arm")))
    rec.log("robot", {"name": "soft-arm"})
    taps: list[list[dict]] = []
    stop = threading.Event()
    logged = [0]

    def table_worker() -> None:
        while not stop.is_set():
            logged[0] += 1
            rec.log("objects", {"objects": [], "n": logged[0]})

    worker = threading.Thread(target=table_worker)
    worker.start()
    try:
        for _ in range(50):
            got: list[dict] = []
            rec.add_tap(lambda r, ns, got=got: got.append(r), latched=True)
            taps.append(got)
    finally:
        stop.set()
        worker.join()
    newest = logged[0]
    for got in taps:
        assert got[0] == {"kind": "robot", "who": "server", "client": None,
                          "data": {"name": "soft-arm"}}
        tables = [r["data"]["n"] for r in got if r["kind"] == "objects"]
        # From the latched table on, every one logged, in order, none missed (the one logged
        # while joining may come twice); reading apart, 6 taps of 50 missed one here.
        assert tables and tables[-1] == newest
        assert all(b - a in (0, 1) for a, b in zip(tables, tables[1:])), tables[:5]
