"""Reachability maps on disk: a hit for the same robot file, a miss when it changes, a corrupt
or mismatched file ignored (with a log line) and recomputed; and the console's planner panel
shows the progress while the child process computes, then how long it took or "from cache"."""

import json
import logging
import shutil
import socket
import time

import numpy as np
import pytest

from console.core import grasp_session
from console.core import reach_job
from console.core.reach_job import ReachCache, ReachOutcome, ReachRequest, start_reach_map
from core import robots
from core.planning.reachability import FAILS, PLANNABLE, ReachMap, grid_axis

ROBOT = robots.load("soft-arm")


@pytest.fixture
def robot_file(tmp_path):
    path = tmp_path / "arm.toml"
    shutil.copy(ROBOT.source, path)
    return path


def a_map(request):
    xs, ys = grid_axis(*request.x_range, request.step), grid_axis(*request.y_range, request.step)
    status = np.random.default_rng(3).choice([0, PLANNABLE, FAILS], (len(ys), len(xs)))
    return ReachMap(xs, ys, status.astype(np.int8), request.radius)


def test_hit_returns_the_saved_map(tmp_path, robot_file):
    request = ReachRequest(robot_file, 0.0165, (-0.3, 0.3), (-0.1, 0.4), 0.05)
    cache = ReachCache(tmp_path / "cache")
    assert cache.load(request) is None
    saved = a_map(request)
    assert cache.save(request, saved) == cache.file(request.key())
    got = cache.load(request)
    np.testing.assert_array_equal(got.status, saved.status)
    np.testing.assert_allclose(got.xs, saved.xs)
    assert got.radius == saved.radius


def test_changed_robot_file_radius_or_grid_misses(tmp_path, robot_file):
    request = ReachRequest(robot_file, 0.0165, (-0.3, 0.3), (-0.1, 0.4), 0.05)
    cache = ReachCache(tmp_path / "cache")
    cache.save(request, a_map(request))
    other_radius = ReachRequest(robot_file, 0.02, (-0.3, 0.3), (-0.1, 0.4), 0.05)
    other_table = ReachRequest(robot_file, 0.0165, (-0.3, 0.35), (-0.1, 0.4), 0.05)
    assert cache.load(other_radius) is None and cache.load(other_table) is None
    robot_file.write_text(robot_file.read_text().replace("kappa_max = 16.7", "kappa_max = 15.0"))
    assert "kappa_max = 15.0" in robot_file.read_text()
    assert cache.load(request) is None


@pytest.mark.parametrize("damage", ["garbage", "truncated", "other key", "wrong shape"])
def test_corrupt_or_mismatched_file_is_ignored_with_a_log_line(tmp_path, robot_file, caplog,
                                                               damage):
    request = ReachRequest(robot_file, 0.0165, (-0.3, 0.3), (-0.1, 0.4), 0.05)
    cache = ReachCache(tmp_path / "cache")
    path = cache.save(request, a_map(request))
    text = path.read_text()
    if damage == "garbage":
        path.write_bytes(b"\x00\xff not json")
    elif damage == "truncated":
        path.write_text(text[: len(text) // 2])
    elif damage == "other key":
        data = json.loads(text)
        data["key"] = "0" * 32
        path.write_text(json.dumps(data))
    else:
        data = json.loads(text)
        data["map"]["status"] = data["map"]["status"][:-1]
        path.write_text(json.dumps(data))
    with caplog.at_level(logging.WARNING, logger="console.core.reach_job"):
        assert cache.load(request) is None
    assert any("ignoring reachability cache" in r.message for r in caplog.records)


def test_start_reach_map_computes_once_then_answers_from_cache(tmp_path, robot_file,
                                                               monkeypatch):
    """A miss runs the child process (with progress), saves the map; the next request (a new
    console: empty memory) answers at once from the file, with the same map."""
    monkeypatch.setattr(reach_job, "_MEMORY", {})
    request = ReachRequest(robot_file, 0.0165, (-0.3, 0.1), (0.0, 0.4), 0.1, levels=0)
    cache = ReachCache(tmp_path / "cache")
    results: list[ReachOutcome] = []
    fractions: list[float] = []
    start_reach_map(request, cache, results.append, fractions.append)
    deadline = time.monotonic() + 120
    while not results and time.monotonic() < deadline:
        time.sleep(0.1)
    cold = results[0]
    assert cold.error is None and not cold.from_cache and "computed in" in cold.note()
    assert fractions and fractions[-1] == 1.0 and fractions == sorted(fractions)
    assert cache.file(request.key()).is_file()
    monkeypatch.setattr(reach_job, "_MEMORY", {})
    start_reach_map(request, cache, results.append)
    assert len(results) == 2  # answered in this thread, before the call returned
    warm = results[1]
    assert warm.from_cache and warm.note() == "from cache"
    np.testing.assert_array_equal(warm.reach.status, cold.reach.status)


def test_unreadable_robot_file_is_an_error_not_a_crash(tmp_path):
    results = []
    start_reach_map(ReachRequest(tmp_path / "missing.toml", 0.0165, (0, 0.1), (0, 0.1)),
                    ReachCache(tmp_path), results.append)
    assert results[0].reach is None and "cannot read the robot file" in results[0].note()


def test_planner_panel_shows_progress_then_time_then_from_cache(tmp_path, monkeypatch):
    """The Grasp planner panel's reachability line counts up while the child computes, ends
    with "computed in … s"; a second console on the same data folder says "from cache" at
    once."""
    import viser

    from console.app import ConsoleApp
    from console.panels.soft_arm import panel_set, planner

    monkeypatch.setattr(reach_job, "_MEMORY", {})
    monkeypatch.setattr(planner.GraspSession, "reach_step", 0.08)
    monkeypatch.setattr(planner.GraspSession, "compute_reach", True)
    monkeypatch.setattr(grasp_session, "SHIPPED_CACHE", tmp_path / "none")
    notes = []

    def run(wait_for: str, timeout: float) -> tuple[str, float]:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        server = viser.ViserServer(host="127.0.0.1", port=port, verbose=False)
        t0 = time.monotonic()
        app = ConsoleApp(ROBOT, server, panels=panel_set.grasp_panels(), data_dir=tmp_path)
        app.start()
        try:
            panel = next(p for p in app.panels if isinstance(p, planner.PlannerPanel))
            deadline = t0 + timeout
            while time.monotonic() < deadline:
                content = panel.reach_note.content
                if not notes or notes[-1] != content:
                    notes.append(content)
                if wait_for in content:
                    return content, time.monotonic() - t0
                time.sleep(0.02)
            raise AssertionError(f"no {wait_for!r} in {notes[-1]!r}")
        finally:
            app.grasp_session.close()
            app.stop()
            server.stop()

    done, _ = run("computed in", 300)
    assert "data-state='done'" in done and "green" in done and "amber" in done
    progress = [n for n in notes if "data-state='computing'" in n]
    assert any("%" in n for n in progress), notes
    percents = [int(n.split("Reachability map: ")[1].split(" %")[0]) for n in progress
                if " %" in n]
    assert percents == sorted(percents)
    notes.clear()
    cached, seconds = run("from cache", 30)
    assert "data-state='done'" in cached and seconds < 2.0
