"""Every 100 Hz loop tick of both arms' real loop processes lands in a console recording: an
independent MCAP reader (the ``mcap`` package, JSON decoded here) finds the ticks of a
grasp-and-place (soft arm, through the console app's recorder) and of a move (extensible arm)
with consecutive tick indices, none missing, and loop times 10 ms apart except where the row
itself says the loop missed deadlines.

No wall-clock figure is asserted: the gaps are the loop's own tick indices and loop times;
the waits only bound how long the processes may take on two busy cores."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import viser
from mcap.reader import make_reader

import ws_client
from console.core.datadir import DataDir
from console.core.model import model_for
from console.core.state import StateStore
from console.recording.recorder import Recorder
from core.control.trials import paper_locations
from core.kinematics import delta as dk
from core.robots import load
from fakes import console_app
from hw_bridge.extensible_process import ExtensibleProcess

SOFT = load("soft-arm")
EXT = load("extensible")


def wait_for(pred, timeout: float = 60.0) -> None:
    ws_client.wait_for(pred, timeout)


def read_ticks(path: Path, topic: str) -> list[dict]:
    with open(path, "rb") as f:
        return [json.loads(m.data) for _, _, m in
                make_reader(f).iter_messages(topics=[topic], log_time_order=True)]


def assert_every_tick(ticks: list[dict]) -> None:
    """Consecutive tick indices; each loop-time step is 10 ms, or the deadlines the tick
    before it says were missed (the loop skips them: nothing was lost in recording)."""
    assert len(ticks) > 100
    idx = [m["tick"] for m in ticks]
    assert idx == list(range(idx[0], idx[0] + len(idx)))
    t = np.array([m["t_s"] for m in ticks])
    missed = np.array([m["missed"] for m in ticks[:-1]])
    np.testing.assert_allclose(np.diff(t), 0.01 * (1 + missed), atol=1e-6)
    for m in ticks:  # the loop's own timing of every tick
        assert m["period_ms"] >= 0 and m["work_ms"] > 0 and m["late_ms"] > -1.0


@pytest.mark.slow(32)  # s on 2 busy cores (2026-12-05)
def test_a_grasp_and_place_on_the_soft_arms_loop_process_is_recorded_tick_by_tick(
        tmp_path: Path) -> None:
    srv = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    app = console_app(SOFT, srv, panels=(), soft_control="process", data_dir=tmp_path)
    ctl = app.services.soft_control
    newest_tick = [-1]

    def note_newest(batch) -> None:  # runs after the recorder's listener, in the same thread
        newest_tick[0] = int(batch.rows[-1, 0])

    ctl.tick_listeners.append(note_newest)
    try:
        wait_for(lambda: ctl.view is not None and ctl.view.snapshot.control is not None)
        path = app.recorder.start("ticks")
        ctl.arm().result(30)
        wait_for(lambda: ctl.view.snapshot.control.prepressurised)
        x, y = paper_locations()["B"]
        ctl.grasp_at(x, y, 0.0165).result(30)
        wait_for(lambda: ctl.view.snapshot.control.phase in ("released", "stopped"), 180.0)
        released = ctl.view.snapshot
        assert released.control.phase == "released", released.control.reason
        # The view comes before the tick batch that holds its tick (the child publishes the
        # view, then drains the tick ring): stop once the recorder was handed that batch.
        wait_for(lambda: newest_tick[0] >= released.tick)
        app.recorder.stop()
    finally:
        app.stop()
        ctl.close()
        srv.stop()
    ticks = read_ticks(path, "/control/ticks")
    assert_every_tick(ticks)
    phases = list(dict.fromkeys(m["phase"] for m in ticks))
    assert {"approach", "grasp", "move_to_bin", "release", "released"} <= set(phases), phases
    moving = [m for m in ticks if m["phase"] == "approach"]
    assert all(m["armed"] and len(m["command_counts"]) == 13 for m in moving)
    assert all(len(m["kappa_target_1_per_m"]) == 6 for m in ticks)
    # The recording's own start: ticks after it only, and the drawn states beside them.
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    topics = {ch.topic: ch.schema_id for ch in summary.channels.values()}
    assert summary.schemas[topics["/control/ticks"]].name == "softarm.SoftArmTick"


def test_a_move_on_the_extensible_arms_loop_process_is_recorded_tick_by_tick(
        tmp_path: Path) -> None:
    store = StateStore(model_for(EXT), mirror_commands=True)
    proc = ExtensibleProcess(EXT, store, "mock", cpus=None, sched_priority=None)
    rec = Recorder(DataDir(tmp_path), model_for(EXT))
    proc.tick_listeners.append(rec.on_ticks)
    batches = [0]

    def count(batch) -> None:  # after the recorder's listener, in the same thread
        if len(batch.rows):
            batches[0] += 1

    proc.tick_listeners.append(count)
    try:
        proc.start()
        assert proc.connecting is not None and proc.connecting.result(30) is None
        wait_for(lambda: proc.snapshot.state == "disarmed")
        path = rec.start("ticks")
        # A batch of disarmed ticks recorded before arming (arming at once, a loaded machine's
        # first batch after the start could begin with the arm's tick: fresh67).
        seen = batches[0]
        wait_for(lambda: batches[0] > seen)
        proc.bridge_controls.arm()
        wait_for(lambda: proc.snapshot.state in ("holding", "following"))
        q = np.array([[0.01, 0.0, 0.05], [0.0, -0.01, 0.04]])
        result = proc.wait(proc.move_to(dk.robot_rack_lengths(EXT, q)), timeout=60)
        assert result is not None and result.ok, result
        wait_for(lambda: proc.snapshot.state == "holding")
        # The child publishes a view, then drains the tick ring: the next batch handed over
        # holds the ticks up to the holding view's (the last tick recorded is the settled arm).
        seen = batches[0]
        wait_for(lambda: batches[0] > seen)
        rec.stop()
    finally:
        proc.close()
    ticks = read_ticks(path, "/control/extensible_ticks")
    assert_every_tick(ticks)
    states = set(m["phase"] for m in ticks)
    assert {"disarmed", "running", "holding"} <= states, states
    for m in ticks:
        assert len(m["encoder_counts"]) == EXT.n_motors
        assert len(m["delta_measured_m"]) == 3 * EXT.n_segments
        assert m["armed"] == (m["phase"] != "disarmed")
        if m["armed"]:  # a demand every armed tick; none written while disarmed
            assert len(m["demand_counts"]) == EXT.n_motors
        else:
            assert "demand_counts" not in m
    # The measured deltas at the end are the move's target (independent: the Δ kinematics).
    last = np.array(ticks[-1]["delta_measured_m"]).reshape(-1, 3)
    assert np.linalg.norm(dk.tip_position(EXT, last) - dk.tip_position(EXT, q)) < 0.003
