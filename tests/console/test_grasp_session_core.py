"""The grasp session is part of the console's headless core: it plans, steps playback on its own
clock and tells its listeners what changed with no viser server at all; the console makes it
(and its 3D layers) for every soft arm, whatever panels are built."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from console.core.grasp_session import GraspSession
from console.core.grasp_state import PARTS
from console.core.table_area import table_extent
from console.recording.lab_feed import feed_grasp
from core.planning.sides import plan_grasp_sided
from core.robots import load
from fakes import FakeClock
from ws_client import wait_for

ROBOT = load("soft-arm")
REPO = Path(__file__).resolve().parents[2]


def headless_session(**kwargs) -> tuple[GraspSession, list, list]:
    """A started session on the straight arm, no server: (session, what listeners were told
    as (view, changed), what the fake recorder logged as (kind, data))."""
    told: list = []
    logged: list = []
    recorder = SimpleNamespace(log=lambda kind, data, *a: logged.append((kind, data)))
    session = GraspSession(ROBOT, table_extent(ROBOT, "planar"), kappa=lambda: np.zeros(6),
                           feed=lambda view, changed: feed_grasp(recorder, view, changed),
                           compute_reach=False, **kwargs)
    session.add_listener(lambda view, changed: told.append((view, changed)))
    return session.start(), told, logged


def test_the_grasp_session_imports_no_viser_and_no_view():
    """In a fresh interpreter: the session's modules load neither viser nor a view layer."""
    code = ("import sys\n"
            "import console.core.grasp_session, console.core.grasp_state\n"
            "bad = sorted(m for m in sys.modules if m.split('.')[0] == 'viser' or m.startswith("
            "('console.scene', 'console.panels', 'console.recording.recorder', 'console.app')))\n"
            "print(','.join(bad))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)}, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == ""


def test_the_console_core_imports_no_viser_and_nothing_above_it():
    """Every import in console/core/ (module level, in functions, under TYPE_CHECKING): no
    viser, and from console only console.core (no scene, panels, recording, app)."""
    import ast

    bad = []
    for path in sorted((REPO / "console" / "core").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level
                     else [])
            for name in names:
                root = name.split(".")[0]
                if root == "viser" or (root == "console" and not name.startswith("console.core")):
                    bad.append(f"{path.relative_to(REPO)}:{node.lineno} imports {name}")
    assert not bad, "\n".join(bad)


def test_a_session_without_a_server_plans_an_object_like_the_planner():
    s, told, logged = headless_session()
    try:
        first = wait_for(lambda: s.view().outcome, 30.0, "the first object planned")
        assert first.obj is not None and first.obj.name == "Object 1"
        name = s.place(-0.12, 0.28)
        out = wait_for(lambda: (o := s.view().outcome) and o.obj and o.obj.name == name and o,
                       30.0, "the placed object planned")
        ref = plan_grasp_sided(ROBOT, np.zeros(6), (-0.12, 0.28),
                               ROBOT.capture.nominal_object_radius)
        assert out.plan is not None and out.plan.success
        np.testing.assert_allclose(out.plan.kappas, ref.kappas, atol=1e-9)
        # Listeners were told the new object before its plan, and then the plan.
        changes = [(v.outcome.obj.name if v.outcome and v.outcome.obj else None, c)
                   for v, c in told]
        placed = next(i for i, (_, c) in enumerate(changes) if "objects" in c and i > 0)
        assert any("plan" in c and who == name for who, c in changes[placed:])
        # The feed recorded the objects and the plan (the recorder's own record format).
        plans = [d for k, d in logged if k == "plan" and d["refusal"] is None]
        assert len(plans[-1]["waypoints"]) == ref.n
        assert any(k == "objects" and [o["name"] for o in d["objects"]] == ["Object 1", name]
                   for k, d in logged)
    finally:
        s.close()
        s.join(5.0)
    assert s._thread is not None and not s._thread.is_alive()


def test_waypoint_playback_steps_on_the_sessions_clock():
    clock = FakeClock(100.0)
    s, told, _ = headless_session(clock=clock)
    try:
        out = wait_for(lambda: s.view().outcome, 30.0, "the first object planned")
        assert out.plan is not None and out.plan.n >= 3
        s.play(True, speed=2.0)                      # a waypoint every 0.5 s of the clock
        assert s.view().playing and s.view().index == 0
        clock.t += 0.5
        wait_for(lambda: s.view().index == 1, 10.0, "one step after 0.5 s")
        s.set_trail(False)                           # the worker runs again; the clock did not
        seen = wait_for(lambda: next((v for v, c in told if "inspect" in c and not v.trail),
                                     None), 10.0, "the trail change told")
        assert seen.index == 1 and s.view().index == 1 and s.view().playing
        clock.t += 0.5
        wait_for(lambda: s.view().index == 2, 10.0, "the next step after another 0.5 s")
    finally:
        s.close()
        s.join(5.0)


@pytest.mark.parametrize("name", ["soft-arm", "extensible"])
def test_the_console_makes_the_grasp_session_whatever_panels(name, monkeypatch):
    import viser

    from console.app import ConsoleApp

    monkeypatch.setattr(GraspSession, "compute_reach", False)
    robot = load(name)
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        app = ConsoleApp(robot, server, panels=())
        if name == "extensible":
            assert app.grasp_session is None and app.grasp_scene is None
            with pytest.raises(RuntimeError, match="not a soft arm"):
                app.soft_arm_grasp()
            return
        session = app.soft_arm_grasp()
        assert session is app.grasp_session
        layers = app.soft_arm_grasp_scene()
        wait_for(lambda: "Object 1" in layers.plan_scene.objects, 10.0, "the object drawn")
        wait_for(lambda: layers.plan_scene.circles.visible, 30.0, "its plan drawn")
        app.stop()
        session.join(5.0)
        assert session._thread is not None and not session._thread.is_alive()
    finally:
        server.stop()


def test_a_listener_added_after_the_start_is_told_the_table_at_once():
    """A panel built after the app made (and started) the session must not wait for the next
    change to show the table: it is told the whole state once, with every part changed. (Panels
    built after the session's first publish showed an empty Objects line until an edit.)"""
    s, told, logged = headless_session()
    try:
        wait_for(lambda: s.view().outcome, 30.0, "the first object planned")
        n_logged = len(logged)
        late: list = []
        s.add_listener(lambda view, changed: late.append((view, changed)))
        view, changed = wait_for(lambda: late and late[0], 10.0, "the late listener told")
        assert changed == PARTS
        assert [o.name for o in view.objects] == ["Object 1"] and view.outcome is not None
        assert len(logged) == n_logged  # the recording is not told the same table again
    finally:
        s.close()


def test_removing_a_listener_waits_for_its_call_in_progress_and_it_is_not_called_again():
    """A closed panel removes its listener from viser's thread while the worker may be inside
    a call to it: the remover returns only after that call ended, and nothing calls it after
    (closed panels wrote into removed widgets). The same for run listeners; a listener may
    remove itself from inside its call."""
    import threading

    s, told, _ = headless_session()
    try:
        wait_for(lambda: s.view().outcome, 30.0, "the first object planned")
        inside, release = threading.Event(), threading.Event()
        calls: list = []

        def slow(view, changed) -> None:
            calls.append(changed)
            inside.set()
            release.wait(10.0)
            calls.append("ended")

        remove = s.add_listener(slow)
        assert inside.wait(10.0), "the new listener is greeted"
        removed = threading.Event()
        remover = threading.Thread(target=lambda: (remove(), removed.set()))
        remover.start()
        assert not removed.wait(0.3), "the remover returned while the call ran"
        release.set()
        assert removed.wait(10.0)
        assert calls[-1] == "ended"
        n = len(calls)
        s.place(-0.1, 0.3)   # a change every listener is told: not the removed one
        wait_for(lambda: any("objects" in c for _, c in told[-3:]), 10.0, "the others told")
        assert len(calls) == n

        run_calls: list = []
        holder: list = []

        def removes_itself(run) -> None:
            run_calls.append(run)
            holder[0]()

        from console.core.run_state import RunView
        running = RunView("settle", None, None, None, None, 1, None, None, 0.0)
        holder.append(s.add_run_listener(removes_itself))
        s.set_run(running)   # the arm began to run: told (and it removes itself)
        assert run_calls == [running]
        s.set_run(None)      # ended: a change, but it removed itself inside its call
        assert run_calls == [running]
    finally:
        s.close()


def test_a_table_emptied_is_no_refusal_but_a_nothing_selected_plan_is():
    """A row that clears the table (or the last object removed) re-plans an empty table: the
    summary goes back to idle, not a red "Refused: No object selected" nobody asked for."""
    from console.scene.plan_view import outcome_html
    s, told, logged = headless_session()
    try:
        wait_for(lambda: s.view().outcome, 30.0, "the first object planned")
        s.set_objects([])
        wait_for(lambda: s.view().outcome is None, 30.0, "the summary back to idle")
        assert 'data-state="idle"' in outcome_html(s.view().outcome)
        name = s.place(-0.12, 0.28)
        wait_for(lambda: (o := s.view().outcome) and o.obj and o.obj.name == name, 30.0,
                 "the placed object planned")
        s.select(None)  # objects on the table, none chosen: Plan says what to do
        out = wait_for(lambda: (o := s.view().outcome) and o.refusal and o, 30.0, "refused")
        assert out.refusal.startswith("No object selected")
        s.remove(name)
        wait_for(lambda: s.view().outcome is None, 30.0, "idle again")
    finally:
        s.close()
        s.join(5.0)


def test_a_removed_objects_name_is_not_given_to_the_next_one():
    """Names identify objects in plans, rows and recordings: after Object 2 is removed (or taken
    to the bin), the next object is Object 3, not a second Object 2; names already on the table
    (a loaded scene's) are skipped."""
    session, _, _ = headless_session()
    try:
        assert [o.name for o in session.view().objects] == ["Object 1"]
        second = session.place(-0.1, 0.3)
        assert second == "Object 2"
        session.remove(second)
        assert session.place(-0.1, 0.3) == "Object 3"
        session.remove("Object 1")
        assert session.place(-0.25, 0.15) == "Object 4"
        assert [o.name for o in session.view().objects] == ["Object 3", "Object 4"]
    finally:
        session.close()
