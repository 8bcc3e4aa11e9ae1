"""``trials --record`` carries what its docstring promises beside the ticks: the loop timing
(on the simulated clock: its 10 ms period, and the wall time each sampled tick took as
``work_ms``) and every plan the state machine got (``/plan``, drawn on ``/scene/plan``), read
back with the ``mcap`` package alone (before, a trials recording had neither), and the robot file
it ran."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from mcap.reader import make_reader

from core.control.trials import paper_locations
from core.labdata.trial_recording import record_trials

OBJECT_R = 0.0165


def test_trials_recording_has_loop_timing_and_the_plan(tmp_path: Path) -> None:
    path = tmp_path / "trial.mcap"
    x, y = paper_locations()["B"]
    (result,) = record_trials(path, "soft-arm", [("B", (x, y, OBJECT_R))], 1, seed=4)
    by_topic: dict[str, list[dict]] = {}
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=True):
            by_topic.setdefault(channel.topic, []).append(json.loads(message.data))
    timing = by_topic["/control/loop_timing"]
    expected = result.sim_s * 10  # sampled at 10 Hz of simulated time
    assert expected * 0.9 <= len(timing) <= expected * 1.1 + 2
    assert all(t["period_ms"] == 10.0 and t["work_ms"] > 0 for t in timing)
    ticks = [t["tick"] for t in timing]
    assert ticks == sorted(ticks) and all(b - a == 10 for a, b in zip(ticks, ticks[1:]))
    plans = by_topic["/plan"]
    assert plans and "refusal" not in plans[0] and plans[0]["waypoints"]
    assert plans[0]["center"] == pytest.approx([x, y], abs=0.01)  # around the object
    assert all(len(w["kappa"]) == 6 for w in plans[0]["waypoints"])
    assert by_topic["/scene/plan"]
    # The robot file the trials ran, as text the robot parser reads back (issue 29.2).
    (robot,) = by_topic["/robot/description"]
    from core.robot_schema import tomllib
    from core.robots import load, parse

    shipped = load("soft-arm")
    assert robot["toml"] == shipped.source.read_text(encoding="utf-8")
    assert parse(tomllib.loads(robot["toml"]), robot["file"]).n_segments == shipped.n_segments
