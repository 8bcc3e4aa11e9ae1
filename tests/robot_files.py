"""Test copies of robot files: a shipped (or test) robot file with a few values changed.

Robot parameters live in data files, so a test that needs other values (a link that tolerates
a starved process, an arm that moves faster than the paper's) writes a copy of the file with
those values and loads it, instead of patching code. :func:`robot_copy` changes ``section.key``
values in place (each must exist exactly once in its section) and keeps everything else,
comments included, so the copy follows every later change of the original.

:data:`QUICK_MOTION` is the soft arm's motion sped up for tests that are about what the
console and the control process do, not about the shipped timing: trajGen's limits three
times the shipped ones and shorter waits (settle, grasp, release). On the simulated arm a
three-object row takes about 27 s instead of 72 s, every object still released without a
re-plan (10 seeds; ``core.control.row.run_row``). Tests of the shipped values themselves (the
paper's 2 s settle, the lease, the link timing) keep the shipped file.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Mapping

from core.robot_text import set_keys

REPO = Path(__file__).resolve().parents[1]
SHIPPED = REPO / "data" / "robots"
TEST_ROBOTS = REPO / "tests" / "data" / "robots"

QUICK_MOTION: Mapping[str, float] = {
    "trajectory.max_velocity": 2.4,        # 1/(m s); shipped 0.8
    "trajectory.max_acceleration": 4.5,    # 1/(m s^2); shipped 1.5
    "trajectory.max_jerk": 30.0,           # 1/(m s^3); shipped 10
    "state_machine.settle_time_s": 0.5,    # shipped 2.0 [paper]
    "state_machine.grasp_time_s": 0.8,     # shipped 1.2
    "state_machine.release_time_s": 0.5,   # shipped 1.0
}

def robot_copy(source: str | Path, dest_dir: Path, changes: Mapping[str, object],
               name: str | None = None) -> Path:
    """Write ``source`` (a shipped robot's name or a TOML path) to ``dest_dir`` with ``changes``
    ({"section.key": value}) applied; returns the new file's path.

    ``name`` renames the robot (default: the source's name with ``-test`` appended), so logs
    and recordings do not pass the copy off as the shipped arm.

    Raises:
        KeyError: a key of ``changes`` is not in its section exactly once.
    """
    path = Path(source) if str(source).endswith(".toml") else SHIPPED / f"{source}.toml"
    text, found = set_keys(path.read_text(), changes)
    wrong = {key: n for key, n in found.items() if n != 1}
    if wrong:
        raise KeyError(f"{path.name}: not found exactly once: {wrong}")
    old = re.search(r'(?m)^name = "([^"]+)"', text)
    assert old is not None, f"{path.name} has no name"
    new_name = name or f"{old.group(1)}-test"
    text = text[:old.start()] + f'name = "{new_name}"' + text[old.end():]
    dest_dir.mkdir(parents=True, exist_ok=True)
    out = dest_dir / f"{new_name}.toml"
    out.write_text(text)
    return out

