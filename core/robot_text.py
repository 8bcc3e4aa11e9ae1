"""Robot files edited as text, key by key, so their comments and layout survive a change.

Design studies write one robot file per variant (:mod:`core.study`) and the tests write copies
with a few values changed (``tests/robot_files.py``); both set ``[section] key = value`` lines in
place here and decide themselves what a key found other than once means.
"""

from __future__ import annotations

import re
from typing import Mapping

SECTION = re.compile(r"^\s*\[([^\]]+)\]\s*(#.*)?$")


def toml_value(value: object) -> str:
    """``value`` as a TOML value: booleans, strings, lists of these, numbers (``repr``)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    return repr(value)


def set_keys(text: str, changes: Mapping[str, object]) -> tuple[str, dict[str, int]]:
    """``text`` with every ``"section.key": value`` of ``changes`` set in place (the line's
    comment kept), and how many lines each key was found on (1 when all is well)."""
    lines = text.splitlines(keepends=True)
    found = {key: 0 for key in changes}
    section = ""
    for i, line in enumerate(lines):
        head = SECTION.match(line)
        if head:
            section = head.group(1).strip()
            continue
        for key, value in changes.items():
            sec, _, field = key.rpartition(".")
            match = re.match(rf"^(\s*{re.escape(field)}\s*=\s*)([^#\n]*?)(\s*(#.*)?\n?)$", line)
            if sec == section and match:
                lines[i] = f"{match.group(1)}{toml_value(value)}{match.group(3)}"
                found[key] += 1
    return "".join(lines), found
