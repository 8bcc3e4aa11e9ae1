"""A recorded run's HTML export draws the console's stage and the arm with the scene layers
themselves: no console app is built (nor imported), and the file holds only the plain-mesh arm --
not the live view's skinned nodes left behind under it."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np

from console.playback.export import recording_html
from console.recording.recorder import Recording
from core.robots import load
from tests.console.test_lab_export import decode_embedded

ROOT = Path(__file__).resolve().parents[2]
SOFT = load("soft-arm")


def short_run() -> Recording:
    times = np.arange(0.0, 0.5, 0.1)
    qs = np.outer(times, [8.0, -4.0, 2.0, 6.0, -3.0, 1.0])
    return Recording("run.jsonl.gz", {"robot": "soft-arm"}, times, qs, ["jog"] * len(times), [])


def test_export_builds_no_console_app() -> None:
    script = textwrap.dedent("""
        import sys
        import numpy as np
        from console.playback.export import recording_html
        from console.recording.recorder import Recording
        from core.robots import load
        rec = Recording("r", {}, np.array([0.0, 0.1]), np.zeros((2, 6)), ["jog"] * 2, [])
        assert recording_html(load("soft-arm"), rec).lower().lstrip().startswith("<!doctype")
        print("console.app" in sys.modules)
    """)
    out = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True,
                         text=True, timeout=120, env={"PYTHONPATH": str(ROOT), "PATH": ""})
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "False"


def test_exported_scene_is_the_stage_and_the_plain_mesh_arm_only() -> None:
    payload, _ = decode_embedded(recording_html(SOFT, short_run(), fps=10.0))
    names = {m.get("name") for _, m in payload["messages"]}
    types = {m["type"] for _, m in payload["messages"]}
    assert {"/table/top", "/table/grid", "/lights/hemisphere", "/arm/body", "/arm/gripper",
            "/arm/palm_point", "/markers/label"} <= names
    assert {"ThemeConfigurationMessage", "SetCameraPositionMessage"} <= types
    assert not any(str(n).startswith("/arm/gripper/") for n in names)  # no skinned leftovers
    assert "SkinnedMeshMessage" not in types
