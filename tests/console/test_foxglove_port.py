"""``serve.py --foxglove-port P`` with P taken: said at once, before the console is built or its
page serves (exit 2), as for the page's own port. Before, the console started, printed its
address and then died with a traceback when the bridge could not bind."""

from __future__ import annotations

import socket
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def test_a_busy_foxglove_port_is_refused_before_anything_serves(tmp_path: Path) -> None:
    with socket.socket() as taken, socket.socket() as free:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        free.bind(("127.0.0.1", 0))
        fox, page = taken.getsockname()[1], free.getsockname()[1]
        free.close()
        run = subprocess.run(
            [sys.executable, str(REPO / "serve.py"), "--robot", "extensible", "--hardware",
             "mock", "--rt-cpu", "none", "--port", str(page), "--foxglove-port", str(fox),
             "--data-dir", str(tmp_path)],
            cwd=REPO, capture_output=True, text=True, timeout=120)
    assert run.returncode == 2, run.stderr[-2000:]
    assert f"--foxglove-port: port {fox} on 127.0.0.1 is already in use" in run.stderr
    assert "Console for" not in run.stdout  # the page never served
    assert "Traceback" not in run.stderr
