"""tests/cpu_times.py counts the CPU seconds of the whole process tree: a child's (and a
grandchild's) work while it runs and after it has been reaped."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest

from cpu_times import tree_cpu_s

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")

BURN = "import time\nend = time.process_time() + {s}\nwhile time.process_time() < end: pass\n"


def test_a_grandchilds_cpu_counts_while_it_runs_and_after_it_is_reaped(tmp_path) -> None:
    import os

    done = tmp_path / "done"
    before = tree_cpu_s(os.getpid())
    # A child that runs a grandchild burning 0.6 s of CPU, says so, and waits.
    code = ("import subprocess, sys, time\n"
            f"subprocess.run([sys.executable, '-c', {BURN.format(s=0.6)!r}])\n"
            f"open({str(done)!r}, 'w').close()\ntime.sleep(60)\n")
    child = subprocess.Popen([sys.executable, "-c", code])
    try:
        deadline = time.monotonic() + 60
        while not done.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert done.exists()
        alive = tree_cpu_s(os.getpid()) - before  # the grandchild, reaped by the live child
        assert alive >= 0.6, alive
    finally:
        child.kill()
        child.wait()
    after = tree_cpu_s(os.getpid()) - before  # the child, reaped by this process
    assert after >= 0.6, after


def test_a_process_outside_the_tree_is_not_counted(tmp_path) -> None:
    import os

    done = tmp_path / "done"
    burn = BURN.format(s=2.0) + f"open({str(done)!r}, 'w').close()\n"
    # Started by a child that exits at once: the burner is reparented outside this tree.
    # This process's own CPU is left out: threads other tests left in this worker may run
    # meanwhile (fresh40: 1.09 s counted beside a 1 s burn on a loaded machine).
    own = time.process_time()
    before = tree_cpu_s(os.getpid())
    subprocess.run([sys.executable, "-c", "import subprocess, sys\n"
                    f"subprocess.Popen([sys.executable, '-c', {burn!r}])\n"], check=True)
    deadline = time.monotonic() + 30
    while not done.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert done.exists()
    spent = tree_cpu_s(os.getpid()) - before - (time.process_time() - own)
    assert spent < 1.0, spent  # the short-lived child's start-up (~0.1 s), not the 2 s burn
    assert tree_cpu_s(2**22 + 7) == 0.0  # no such process: nothing
