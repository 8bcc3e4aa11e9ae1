"""An operator's table edits are recorded as theirs: "Add object", a click that places one,
Remove and a loaded scene each write an ``/operator/actions`` entry naming who did it (their
display name and client id), where the object is (mm in words, m in the details). Before, an
"Add object" showed only as a ``/objects`` record by ``who: "server"`` with no action."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from mcap.reader import make_reader
from test_row_console import rig  # noqa: F401

from console.core.datadir import DataDir
from fakes import click_at, user


def test_add_click_and_remove_are_recorded_with_who_did_them(rig, tmp_path: Path) -> None:
    app, objects_panel, _, _, operator, _ = rig
    app.recorder.data = DataDir(tmp_path)
    path = app.recorder.start("actions", operator)
    user(objects_panel.x, operator, 100.0)
    user(objects_panel.y, operator, 250.0)  # Object 1 (selected) typed to (100, 250) mm
    user(objects_panel.x, operator, -150.0)  # ... then (-150, 250) mm
    user(objects_panel.add_button, operator)  # the typed spot is Object 1's: placed beside it
    click_at(objects_panel, operator, 0.05, 0.32)
    user(objects_panel.remove_button, operator)  # the clicked one is selected: removed
    app.recorder.stop()
    with open(Path(path), "rb") as f:
        actions = [json.loads(m.data) for _, ch, m in make_reader(f).iter_messages()
                   if ch.topic == "/operator/actions"]
    ours = [a for a in actions if "object" in a["what"]]
    assert [a["what"].split(" at ")[0] for a in ours] == [
        "edited object 'Object 1'", "edited object 'Object 1'", "edited object 'Object 1'",
        "added object 'Object 2'",
        "placed object 'Object 3'", "removed object 'Object 3'"]
    assert all(a["who"] == "Alice" and a["client"] == str(operator.client_id) for a in ours)
    added = ours[3]
    assert added["what"] == "added object 'Object 2' at (-90, 250) mm, r 16.5 mm"  # beside 1
    details = json.loads(added["details"])
    assert details["object"] == "Object 2"
    assert (details["x_m"], details["y_m"], details["r_m"]) == pytest.approx((-0.09, 0.25, 0.0165))
    placed = json.loads(ours[4]["details"])
    assert (placed["x_m"], placed["y_m"]) == pytest.approx((0.05, 0.32))
