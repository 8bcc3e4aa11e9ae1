"""Every loop tick in ``trials --record`` (simulated clock) and the export's tables: an
independent MCAP reader (the ``mcap`` package, JSON decoded here) finds one message per 10 ms
tick, none missing, over 60 s of grasp-and-place; ``python -m core.labdata export`` writes CSV
and Parquet tables whose rows are those messages; the tick ring counts what it had to drop."""

from __future__ import annotations

import csv
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from core.control.trials import paper_locations
from core.labdata.ticks import SoftArmTicks, TickRing
from core.labdata.trial_recording import record_trials

ROOT = Path(__file__).resolve().parents[2]
OBJECT_R = 0.0165  # the paper's 3.3 cm object


def read_ticks(path: Path, topic: str = "/control/ticks") -> list[tuple[int, dict]]:
    """(log ns, message) of ``topic``, read with the mcap package alone."""
    with open(path, "rb") as f:
        return [(m.log_time, json.loads(m.data))
                for _, _, m in make_reader(f).iter_messages(topics=[topic],
                                                            log_time_order=True)]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list]:
    """Grasp-and-place trials at spots B and C: over 60 s of simulated loop time."""
    path = tmp_path_factory.mktemp("ticks") / "trials.mcap"
    spots = paper_locations()
    objects = [(s, (*spots[s], OBJECT_R)) for s in ("B", "C")]
    results = record_trials(path, "soft-arm", objects, 1, seed=4)
    return path, results


def test_every_tick_of_60_s_of_grasp_and_place_is_recorded_at_100_hz(recorded) -> None:
    path, results = recorded
    assert any(r.success for r in results), [r.failure for r in results]
    assert sum(r.ticks for r in results) * 0.01 >= 60.0
    ticks = read_ticks(path)
    assert len(ticks) == sum(r.ticks for r in results)  # every tick of every trial
    assert any("kappa_measured_1_per_m" not in m for _, m in ticks)  # occluded: omitted
    # Per trial: ticks 1..n, consecutive, 10 ms apart in loop time and in log time.
    starts = [i for i, (_, m) in enumerate(ticks) if m["tick"] == 1]
    assert len(starts) == len(results)
    for a, b, r in zip(starts, starts[1:] + [len(ticks)], results):
        run = [m for _, m in ticks[a:b]]
        assert [m["tick"] for m in run] == list(range(1, r.ticks + 1))
        gaps = np.diff([m["t_s"] for m in run])
        assert np.allclose(gaps, 0.01, atol=1e-9)
        log_gaps = np.diff([ns for ns, _ in ticks[a:b]]) / 1e9
        assert np.allclose(log_gaps, 0.01, atol=2e-9)
        phases = [m["phase"] for m in run]
        if r.success:  # the state machine's way through a grasp-and-place, in order
            seen = list(dict.fromkeys(phases))
            assert seen[0] == "idle" and seen[-1] == "released", seen
            assert {"approach", "grasp", "move_to_bin", "release"} <= set(seen), seen
    m = ticks[len(ticks) // 2][1]
    assert len(m["kappa_measured_1_per_m"]) == 6 and len(m["command_counts"]) == 13
    assert "period_ms" not in m  # no real clock on a simulated run: omitted, not null
    assert all(v is not None for _, msg in ticks for v in msg.values())


def test_export_writes_one_table_per_channel_whose_rows_are_the_ticks(recorded,
                                                                      tmp_path: Path) -> None:
    pq = pytest.importorskip("pyarrow.parquet")
    path, _ = recorded
    out = tmp_path / "tables"
    done = subprocess.run([sys.executable, "-m", "core.labdata", "export", str(path),
                           "--out", str(out)], cwd=ROOT, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    with open(path, "rb") as f:
        topics = {ch.topic for ch in make_reader(f).get_summary().channels.values()}
    stems = {t.strip("/").replace("/", "_") for t in topics}
    assert {p.stem for p in out.glob("*.csv")} == stems
    assert {p.stem for p in out.glob("*.parquet")} == stems

    ticks = read_ticks(path)
    with open(out / "control_ticks.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    table = pq.read_table(out / "control_ticks.parquet").to_pylist()
    assert len(rows) == len(table) == len(ticks)
    for (ns, m), row, prow in zip(ticks, rows, table):
        assert int(row["log_time_ns"]) == ns == prow["log_time_ns"]
        assert int(row["tick"]) == m["tick"] == prow["tick"]
        assert float(row["t_s"]) == m["t_s"] == prow["t_s"]
        assert row["phase"] == m["phase"] == prow["phase"]
        for i in range(6):
            for key in ("kappa_target_1_per_m", "kappa_measured_1_per_m"):
                col = f"seg{i + 1}_{key}"
                if key in m:
                    assert float(row[col]) == m[key][i] == prow[col]
                else:  # no measurement that tick (markers occluded): an empty cell
                    assert row[col] == "" and prow[col] is None
        assert [float(row[f"cmd{j + 1}_counts"]) for j in range(13)] == m["command_counts"]
        assert row["period_ms"] == "" and prow["period_ms"] is None  # omitted: empty cell
    # Another channel: units in its column names.
    with open(out / "objects.csv", newline="") as f:
        header = next(csv.reader(f))
    assert "log_time_ns" in header and "timestamp_ns" in header


def test_the_ring_drains_in_order_and_counts_ticks_it_had_to_drop() -> None:
    ring = TickRing(SoftArmTicks(2), capacity=8)

    class C:  # a Telemetry's fields the layout reads
        armed, phase = True, "approach"
        kappa_target = np.array([1.0, 2.0])
        kappa_ref = np.array([1.5, 2.5])
        kappa_meas = None  # lost measurement: NaN in the row, omitted in the message
        commands = np.arange(5.0)

    for k in range(1, 4):
        ring.add(k, k * 0.01, None, C.commands, C, (0.1, 10.0, 0.5, 0.1, 0.2, 0.1), 0)
    b = ring.drain()
    assert b is not None and b.dropped == 0 and list(b.rows[:, 0]) == [1, 2, 3]
    assert ring.drain() is None
    for k in range(4, 24):  # 20 ticks into a ring of 8 before the next drain
        ring.add(k, k * 0.01, None, C.commands, C)
    b = ring.drain()
    assert b.dropped == 13 and list(b.rows[:, 0]) == list(range(17, 24))  # capacity - 1 kept
    assert all(math.isnan(v) for v in b.rows[0, 11 + 4:11 + 6])  # kappa_meas unknown
