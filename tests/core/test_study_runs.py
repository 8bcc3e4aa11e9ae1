"""core.study's runs: rows completing in any order, a killed study resumed, Ray's numbers (issue 30).

The Ray test needs Ray (the ``study`` extra, not in ``test``: ~60 s to install): it is skipped
when Ray is missing, except under ``STUDY_RAY=1``, where a missing Ray fails it.
"""

from __future__ import annotations

import importlib.util
import json
import os
import time
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator

import pyarrow.parquet as pq
import pytest

from core.study import StudySpec, run_study
from core.study.__main__ import main, variant_map

FAST = StudySpec(objects=0, ik_grid=0, slip_points=0)
"""Extensible variants in well under a second each: the workspace volume only."""
VARY = {"segments.rack_max": [0.3, 0.35, 0.41]}


class Killed(BaseException):
    """The study's process killed (what a KeyboardInterrupt or a SIGTERM does to the loop)."""


def dying_map(rows_before_kill: int, seen: list[str]) -> Callable[..., Iterator[Any]]:
    """A map that completes the jobs last first and is killed after ``rows_before_kill`` rows."""
    def run(fn: Callable[[Any], Any], jobs: Iterable[Any]) -> Iterator[Any]:
        for n, job in enumerate(reversed(list(jobs))):
            seen.append(job[0])
            if n == rows_before_kill:
                raise Killed
            yield fn(job)
    return run


def test_a_killed_study_keeps_its_finished_variants_in_any_order_and_resumes(tmp_path: Path) -> None:
    fresh = run_study("extensible", VARY, tmp_path / "fresh", FAST)
    names = [r["variant"] for r in fresh]
    out = tmp_path / "killed"
    seen: list[str] = []
    with pytest.raises(Killed):
        run_study("extensible", VARY, out, FAST, map_fn=dying_map(2, seen))
    # The last two variants completed first; both are stored, the first is not.
    assert sorted(p.stem for p in (out / "variants").glob("*.json")) == sorted(names[1:])
    assert not (out / "results.csv").exists()
    # A kill while a row was being stored leaves no half row: a torn file is computed again.
    (out / "variants" / f"{names[2]}.json").write_text('{"variant": "exten')
    resumed: list[str] = []

    def recording_map(fn: Callable[[Any], Any], jobs: Iterable[Any]) -> Iterator[Any]:
        for job in jobs:
            resumed.append(job[0])
            yield fn(job)

    rows = run_study("extensible", VARY, out, FAST, map_fn=recording_map)
    assert resumed == [names[0], names[2]]
    assert rows == fresh
    assert pq.read_table(out / "results.parquet").to_pylist() == \
        pq.read_table(tmp_path / "fresh" / "results.parquet").to_pylist()


def gated(job: tuple[int, str]) -> tuple[int, str]:
    """Job 0 finishes only once the consumer has received another row (or after 30 s)."""
    index, flag = job
    if index == 0:
        deadline = time.monotonic() + 30.0
        while not Path(flag).exists():
            if time.monotonic() > deadline:
                return index, "timed out"
            time.sleep(0.05)
        return index, "released"
    return index, "done"


def test_the_local_pool_hands_rows_back_as_they_complete(tmp_path: Path) -> None:
    flag = tmp_path / "first-row-received"
    with variant_map(2) as map_fn:
        rows = map_fn(gated, [(0, str(flag)), (1, str(flag))])
        first = next(rows)
        flag.touch()
        second = next(rows)
    # An ordered map would wait for job 0, which waits for the consumer's first row.
    assert (first, second) == ((1, "done"), (0, "released"))


def test_cli_with_jobs_writes_the_same_rows_as_in_process(tmp_path: Path) -> None:
    args = ["--robot", "extensible", "--vary", "segments.rack_max=0.3,0.41",
            "--ik-grid", "0", "--slip-points", "0"]
    assert main([*args, "--out", str(tmp_path / "pool"), "--jobs", "2"]) == 0
    one = run_study("extensible", {"segments.rack_max": [0.3, 0.41]}, tmp_path / "one", FAST)
    assert pq.read_table(tmp_path / "pool" / "results.parquet").to_pylist() == one


def test_ray_missing_is_one_line_before_any_work(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "ray" else real(name, *a))
    out = tmp_path / "s"
    assert main(["--robot", "extensible", "--vary", "segments.rack_max=0.3", "--out", str(out),
                 "--ray", "local"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["error: --ray needs Ray: pip install '.[study]'"]
    assert not out.exists()


def _ray_or_skip() -> None:
    if importlib.util.find_spec("ray") is None:
        if os.environ.get("STUDY_RAY") == "1":
            pytest.fail("STUDY_RAY=1 but ray is not installed (pip install '.[study]')")
        pytest.skip("ray is not installed (the 'study' extra); STUDY_RAY=1 makes this a failure")


def test_a_local_ray_on_two_cpus_gives_identical_tables(tmp_path: Path) -> None:
    _ray_or_skip()
    spec = StudySpec(objects=0, ik_grid=2, slip_points=1, slip_repeats=2)
    vary = {"segments.rack_max": [0.3, 0.41]}
    here = run_study("extensible", vary, tmp_path / "here", spec)
    with variant_map(1, "local") as map_fn:
        on_ray = run_study("extensible", vary, tmp_path / "ray", spec, map_fn=map_fn)
    assert on_ray == here
    assert pq.read_table(tmp_path / "ray" / "results.parquet").to_pylist() == \
        pq.read_table(tmp_path / "here" / "results.parquet").to_pylist()
    assert (tmp_path / "ray" / "results.csv").read_text() == \
        (tmp_path / "here" / "results.csv").read_text()
    stored = json.loads((tmp_path / "ray" / "variants" / f"{here[1]['variant']}.json").read_text())
    assert stored == here[1] and "tip_ik_success" in stored and "slip_open_spread_m" in stored
