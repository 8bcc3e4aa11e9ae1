"""Trials: end-to-end grasp-and-place on the simulated arm through the loop runner; the CLI."""

import json

import numpy as np
import pytest

from core import robots
from core.control import trials
from core.control.trials.__main__ import main as trials_main
from core.planning.grasp import plan_grasp


@pytest.fixture(scope="module")
def arm():
    return robots.load("soft-arm")


def test_paper_locations_are_in_the_left_quadrant_and_plannable(arm):
    spots = trials.paper_locations()
    assert list(spots) == ["A", "B", "C", "D", "E"]
    r = arm.capture.nominal_object_radius
    for x, y in spots.values():
        assert x < 0 < y and np.hypot(x, y) < arm.reach
        plan = plan_grasp(arm, np.zeros(6), (x, y), r)
        assert len(plan.kappas) >= 1
    pts = np.array(list(spots.values()))
    assert np.ptp(pts[:, 0]) > 0.1 and np.ptp(pts[:, 1]) > 0.1  # spread over the workspace


def test_two_trials_succeed_end_to_end(arm):
    results = trials.run_trials("soft-arm", [("B", (-0.22, 0.20, 0.0165)),
                                             ("E", (-0.08, 0.33, 0.0165))], 1, 0)
    assert [r.success for r in results] == [True, True], [r.failure for r in results]
    for r in results:
        assert r.failure is None and r.approach_s > 0 and r.return_s > 0
        assert r.sim_s > r.approach_s + r.return_s
        # The simulated object really travelled from its spot to the bin drop area.
        drop = trials.bin_drop_point(arm, 0.0165)
        assert np.hypot(*(np.subtract(r.final_object, drop))) < 0.05
        assert np.hypot(*(np.subtract(r.final_object, r.object[:2]))) > 0.05


def test_unreachable_object_fails_with_the_planners_reason(arm):
    r = trials.run_trial(arm, (-0.6, 0.1, 0.0165), 0, time_limit_s=10.0)
    assert not r.success and r.failure.startswith("planner refused")


def test_cli_json_shape(capsys):
    assert trials_main(["--object", "-0.16", "0.28", "0.0165", "--repeats", "1", "--seed", "3",
                        "--json", "--workers", "0"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) == {"trials", "loop"}
    (t,) = out["trials"]
    assert list(t) == ["object", "success", "failure", "approach_s", "return_s"]
    assert t["object"] == [-0.16, 0.28, 0.0165] and isinstance(t["success"], bool)
    assert out["loop"]["clock"] == "simulated" and out["loop"]["trials"] == 1


def test_cli_rejects_bad_objects(capsys):
    with pytest.raises(SystemExit):
        trials_main(["--object", "0", "0.2", "-1"])
    assert "R > 0" in capsys.readouterr().err
