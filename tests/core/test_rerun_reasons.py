"""A rerun test's first failure is printed (tests/rerun_reasons.py): run pytest on a tiny file
whose test fails once and then passes, with the suite's conftest and scripts/test's rerun flags,
and read its output."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from conftest import REPO

FLAKY = '''
import pathlib, sys

def test_fails_once(tmp_path_factory):
    mark = pathlib.Path(__file__).with_name("tried")
    if not mark.exists():
        mark.write_text("1")
        print("emulator: watchdog tripped at t = 12.3 s", file=sys.stderr)
        lines = "\\n".join(f"detail line {i}" for i in range(60))
        assert False, "first try failed: sentinel 4711\\n" + lines

def test_steady():
    assert 1 + 1 == 2
'''


def run_suite_flags(tmp_path: Path, source: str) -> str:
    """pytest on ``source`` with tests/conftest.py (as a plugin) and ``--reruns 1 -rR``."""
    (tmp_path / "test_flaky.py").write_text(source)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO / "tests"), str(REPO)])}
    env.pop("SUITE_PART", None)
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", "-p", "conftest", "-p", "no:cacheprovider",
         "--reruns", "1", "-rR", "-q", "test_flaky.py"],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout


def test_a_rerun_prints_why_its_first_try_failed(tmp_path: Path) -> None:
    out = run_suite_flags(tmp_path, FLAKY)
    assert "1 rerun" in out and "2 passed" in out
    head = "RERUN test_flaky.py::test_fails_once (call, "
    # once at the time of the rerun, once in the summary section
    assert out.count(head) == 2, out
    assert "): AssertionError: first try failed: sentinel 4711" in out
    section = out.split("rerun reasons (the first failure of each rerun test)", 1)[1]
    assert "sentinel 4711" in section
    assert "detail line 59" in section  # the traceback's tail ...
    assert "detail line 5\n" not in section  # ... and only its tail (30 lines)
    assert "emulator: watchdog tripped at t = 12.3 s" in section  # its stderr
    assert "test_steady" not in section


def test_no_rerun_no_section(tmp_path: Path) -> None:
    out = run_suite_flags(tmp_path, "def test_ok():\n    assert True\n")
    assert "1 passed" in out
    assert "rerun reasons" not in out and "RERUN" not in out
