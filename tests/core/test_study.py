"""core.study: a design study's rows against independent expectations (issue 30)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from core.control.capture import characterise
from core.robots import SoftArm, load
from core.study import StudySpec, run_study

REPO = Path(__file__).resolve().parents[2]
TINY = StudySpec(objects=0, seeds=1, reach_step=0.04, capture_spacing=0.02, ik_grid=0,
                 slip_points=0)


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "core.study", *args], cwd=REPO,
                          capture_output=True, text=True, timeout=60)


@pytest.mark.parametrize("vary, names", [("segments.bogus=1", "segments.bogus"),
                                         ("segments.count=99", "segments.count"),
                                         ("segments.length=abc", "segments.length")])
def test_bad_input_is_one_line_naming_the_key_and_does_nothing(tmp_path: Path, vary: str,
                                                               names: str) -> None:
    out = tmp_path / "study"
    proc = _cli("--robot", "soft-arm", "--vary", vary, "--out", str(out))
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1 and names in proc.stderr
    assert not out.exists()


def test_tiny_study_tables_robot_files_metrics_and_resume(tmp_path: Path) -> None:
    out = tmp_path / "study"
    rows = run_study("soft-arm", {"segments.length": [0.05, 0.0627]}, out, TINY)
    table = pq.read_table(out / "results.parquet").to_pylist()
    assert [r["variant"] for r in table] == [r["variant"] for r in rows]
    assert [r["segments.length"] for r in table] == [0.05, 0.0627]
    assert all(r["error"] == "" for r in table)
    assert (out / "results.csv").read_text().count("\n") == 3
    report = (out / "report.html").read_text()
    assert "<svg" in report and "http" not in report.replace("http://www.w3.org/2000/svg", "")
    for r in table:
        robot = load(out / f"{r['variant']}.toml")
        assert isinstance(robot, SoftArm)
        assert robot.lengths[0] == pytest.approx(r["segments.length"])
    # A longer arm reaches a larger area of the table.
    assert table[1]["reachable_area_m2"] > table[0]["reachable_area_m2"] > 0
    # The capture-region area is the single-file function's success cells times the cell area.
    robot = load(out / f"{table[0]['variant']}.toml")
    assert isinstance(robot, SoftArm)
    cmap = characterise(robot, robot.capture.nominal_object_radius, spacing=0.02)
    assert table[0]["capture_area_m2"] == pytest.approx(cmap.successes * 0.02 ** 2)
    # Resume: a finished variant is not recomputed (its stored row is reused as is).
    stored = out / "variants" / f"{table[0]['variant']}.json"
    stored.write_text(stored.read_text().replace('"error": ""', '"error": "kept"'))
    again = run_study("soft-arm", {"segments.length": [0.05, 0.0627]}, out, TINY)
    assert again[0]["error"] == "kept"
    assert again[1]["reachable_area_m2"] == rows[1]["reachable_area_m2"]


def test_extensible_longer_racks_reach_a_larger_volume(tmp_path: Path) -> None:
    rows = run_study("extensible", {"segments.rack_max": [0.3, 0.41]}, tmp_path / "s", TINY)
    assert all(r["error"] == "" for r in rows)
    assert rows[1]["workspace_volume_m3"] > rows[0]["workspace_volume_m3"] > 0


def test_a_failing_variant_is_a_row_with_its_reason(tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    import core.study as study

    def boom(*_: object) -> dict[str, float]:
        raise RuntimeError("planner exploded")

    monkeypatch.setattr(study, "extensible_metrics", boom)
    rows = run_study("extensible", {"segments.rack_max": [0.3, 0.41]}, tmp_path / "s", TINY)
    assert [r["error"] for r in rows] == ["RuntimeError: planner exploded"] * 2
    assert (tmp_path / "s" / "results.parquet").exists()


def test_process_pool_gives_the_same_numbers_as_in_process(tmp_path: Path) -> None:
    vary = {"segments.rack_max": [0.3, 0.41]}
    import concurrent.futures as cf
    import multiprocessing as mp
    one = run_study("extensible", vary, tmp_path / "a", TINY)
    with cf.ProcessPoolExecutor(2, mp_context=mp.get_context("spawn")) as pool:
        two = run_study("extensible", vary, tmp_path / "b", TINY, map_fn=pool.map)
    assert one == two
