"""Results out of the CLIs: trials and capture write CSV (one row per trial / grid point, units
in the header) that agrees with their JSON; ``trials --record`` writes an MCAP of the trials
through the console's writer (checked with the independent reader); progress bars appear on a
terminal only."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from core.control.capture import CaptureMap
from core.labdata.progress import progress_bar, trial_progress
from core.labdata.results_csv import CAPTURE_COLUMNS, TRIAL_COLUMNS
from core.robots import load

SOFT = load("soft-arm")

try:  # the CLIs live in the packages' __main__ once trials and capture are packages
    from core.control.capture.__main__ import main as capture_main
    from core.control.trials.__main__ import main as trials_main
except ImportError:
    from core.control.capture import main as capture_main
    from core.control.trials import main as trials_main


def read_csv(path: Path) -> tuple[list[str], list[dict[str, str]]]:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], [dict(zip(rows[0], r)) for r in rows[1:]]


def test_trials_csv_and_recording_agree_with_the_json(tmp_path, capsys) -> None:
    out_csv, out_mcap = tmp_path / "trials.csv", tmp_path / "trials.mcap"
    assert trials_main(["--object", "-0.22", "0.20", "0.0165", "--repeats", "1", "--seed", "0",
                        "--workers", "0", "--json", "--csv", str(out_csv),
                        "--record", str(out_mcap)]) == 0
    captured = capsys.readouterr()
    assert captured.err == ""  # not a terminal: no progress output
    (t,) = json.loads(captured.out)["trials"]
    header, rows = read_csv(out_csv)
    assert tuple(header) == TRIAL_COLUMNS and len(rows) == 1
    assert "x [m]" in header and "approach [s]" in header and "tick work p99 [ms]" in header
    row = rows[0]
    assert [float(row[k]) for k in ("x [m]", "y [m]", "r [m]")] == t["object"]
    assert row["success"] == ("true" if t["success"] else "false") and t["success"]
    assert float(row["approach [s]"]) == t["approach_s"]
    assert float(row["return [s]"]) == t["return_s"]

    with open(out_mcap, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        f.seek(0)
        msgs = [(c.topic, m.log_time, json.loads(m.data))
                for _, c, m in make_reader(f).iter_messages(log_time_order=False)]
    names = {summary.channels[c].topic: summary.schemas[summary.channels[c].schema_id].name
             for c in summary.channels}
    assert names["/arm/scene"] == "foxglove.SceneUpdate" and names["/events"] == "foxglove.Log"
    stamps = [ns for _, ns, _ in msgs]
    assert stamps == sorted(stamps)
    sim_s = float(row["simulated [s]"])
    span = (stamps[-1] - stamps[0]) / 1e9
    assert span == pytest.approx(sim_s, abs=0.02)  # log time is the simulated clock
    configs = [b for t_, _, b in msgs if t_ == "/arm/configuration"]
    assert len(configs) == pytest.approx(sim_s * 10, abs=2)  # 10 Hz of a 100 Hz loop
    phases = [b["phase"] for t_, _, b in msgs if t_ == "/control/phase"]
    assert phases[-1] == "released" and len(set(phases)) >= 4
    actions = [b["what"] for t_, _, b in msgs if t_ == "/operator/actions"]
    assert actions[0].startswith("trial 1/1 start: spot #1") and actions[-1] == \
        "trial 1/1 end: success"
    objects = [b["objects"][0] for t_, _, b in msgs if t_ == "/objects"]
    assert (objects[0]["x"], objects[0]["y"]) == (-0.22, 0.20)
    final = np.array([float(row["final x [m]"]), float(row["final y [m]"])])
    assert np.hypot(objects[-1]["x"] - final[0], objects[-1]["y"] - final[1]) < 0.01
    assert np.hypot(*(final - np.array([-0.22, 0.20]))) > 0.05  # it really moved to the bin

    from console.core.model import model_for  # the console replays it, with its markers
    from console.recording.recorder import load_recording
    from console.playback.replay_markers import markers_of
    rec = load_recording(out_mcap, model_for(SOFT))
    assert len(rec.times) == len(configs) and rec.duration == pytest.approx(span, abs=0.2)
    cats = [m.category for m in markers_of(rec)]
    assert cats[0] == cats[-1] == "action" and cats.count("phase") == len(phases)

    with pytest.raises(SystemExit):  # never overwrites a recording
        trials_main(["--object", "-0.22", "0.20", "0.0165", "--record", str(out_mcap)])
    assert "need a new file ending in .mcap" in capsys.readouterr().err


def test_capture_csv_has_one_row_per_grid_point_matching_the_json(tmp_path, capsys) -> None:
    out_json, out_csv = tmp_path / "cap.json", tmp_path / "cap.csv"
    assert capture_main(["--spacing", "0.01", "--out", str(out_json), "--csv",
                         str(out_csv)]) == 0
    assert capsys.readouterr().err == ""
    cmap = CaptureMap.load(out_json)
    header, rows = read_csv(out_csv)
    assert tuple(header) == CAPTURE_COLUMNS and len(rows) == len(cmap.xs) * len(cmap.ys)
    names = {1: "success", 0: "failure", -1: "infeasible"}
    for row in rows[:: max(1, len(rows) // 40)]:
        i = int(np.argmin(np.abs(cmap.xs - float(row["x [m]"]))))
        j = int(np.argmin(np.abs(cmap.ys - float(row["y [m]"]))))
        assert row["outcome"] == names[int(cmap.outcome[j, i])]
        assert float(row["success rate"]) == pytest.approx(cmap.rate[j, i])
        inside = np.hypot(cmap.xs[i] - cmap.model.center[0],
                          cmap.ys[j] - cmap.model.center[1]) <= cmap.model.diameter / 2
        assert row["in model disc"] == ("true" if inside else "false")
    assert sum(r["outcome"] == "success" for r in rows) == cmap.successes
    assert {r["object r [m]"] for r in rows} == {repr(cmap.radius)}


def test_progress_shows_on_a_terminal_only() -> None:
    class Tty(io.StringIO):
        def isatty(self) -> bool:
            return True

    tty, pipe = Tty(), io.StringIO()
    for stream in (tty, pipe):
        bar = progress_bar(3, "trials", unit="trial", stream=stream, mininterval=0)
        for _ in range(3):
            bar.update(1)
        bar.close()
    assert "trials" in tty.getvalue() and "3/3" in tty.getvalue()
    assert pipe.getvalue() == ""
    with trial_progress(2, force=False) as progress:  # the callback works without a bar too
        progress(1, 2, type("R", (), {"success": True})())
        assert progress.ok == 1


def test_the_trial_sampler_takes_snapshots_or_bare_telemetry() -> None:
    """A loop that hands ``until`` only the telemetry still gets phases, states, the object and
    loop timing (on the simulated clock: the 10 ms period, and the wall time per tick)."""
    from types import SimpleNamespace

    from core.labdata.trial_recording import TrialSampler

    def tel(t: float, phase: str, xy: tuple[float, float]) -> SimpleNamespace:
        return SimpleNamespace(t=t, phase=phase, reason=None, armed=True, tracking_ok=True,
                               gripper_closed=False, waypoint=0, n_waypoints=2, replans=0,
                               kappa_meas=np.ones(6), kappa_ref=np.zeros(6), object_xy=xy)

    bare, full = TrialSampler(hz=50.0), TrialSampler(hz=50.0)
    for k in range(1, 7):
        t = tel(k * 0.01, "approach" if k < 4 else "grasp", (0.1 + 0.01 * k, 0.2))
        bare(t)
        full(SimpleNamespace(tick=k, t=t.t, control=t, period_ms=10.0, work_ms=0.4,
                             overruns=0, fault=None))
    bare(None)
    simulated = [r["data"] for r in bare.records if r["kind"] == "timing"]
    assert all(d["period_ms"] == 10.0 and d["work_ms"] >= 0.0 for d in simulated)
    assert [d["tick"] for d in simulated] == [2, 4, 6]
    for sampler, timing in ((bare, 3), (full, 3)):
        kinds = [r["kind"] for r in sampler.records]
        assert kinds.count("phase") == 2 and kinds.count("state") == 3
        assert kinds.count("timing") == timing and kinds.count("objects") == 3
        assert [r["t"] for r in sampler.records if r["kind"] == "state"] == [0.02, 0.04, 0.06]
