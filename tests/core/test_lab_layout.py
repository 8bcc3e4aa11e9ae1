"""The shipped Foxglove/Lichtblick layout (``docs/foxglove-layout.json``) shows what the lab doc
promises -- the arm, the plan, the phase, the tracking and loop-timing plots -- and every message
path it plots exists in the datatypes Lichtblick derives from the channel's schema
(``tests/lichtblick_schema.py``), so no panel opens empty because of a typo or a renamed field."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pytest

from core.labdata.channels import CHANNELS, TICK_CHANNELS
from tests.lichtblick_schema import parse_json_schema

LAYOUT = Path(__file__).resolve().parents[2] / "docs" / "foxglove-layout.json"
SPECS = {s.topic: s for s in CHANNELS + TICK_CHANNELS}


def _panels(node: Any) -> list[str]:
    if isinstance(node, str):
        return [node]
    return _panels(node["first"]) + _panels(node["second"])


def resolve(path: str) -> str:
    """The Lichtblick datatype a message path ends on ("float64", "string", "bool" ...)."""
    topic = max((t for t in SPECS if path == t or path.startswith(t + ".")), key=len,
                default=None)
    assert topic is not None, f"{path}: no such topic"
    spec = SPECS[topic]
    types = parse_json_schema(spec.schema, spec.schema_name)
    current = spec.schema_name
    for part in path[len(topic) + 1:].split("."):
        m = re.fullmatch(r"(\w+)(\[\d+\])?", part)
        assert m, f"{path}: bad step {part!r}"
        fields = {f["name"]: f for f in types[current]}
        assert m.group(1) in fields, f"{path}: {current} has no field {m.group(1)!r}"
        field = fields[m.group(1)]
        assert bool(field.get("isArray")) == bool(m.group(2)), f"{path}: index mismatch"
        current = field["type"]
    return current


def test_the_layout_shows_arm_plan_phase_tracking_and_timing() -> None:
    layout = json.loads(LAYOUT.read_text())
    configs = layout["configById"]
    shown = _panels(layout["layout"])
    assert sorted(shown) == sorted(configs)  # every panel placed, none without a config
    three_d = [configs[p] for p in shown if p.startswith("3D!")]
    assert len(three_d) == 1 and three_d[0]["followTf"] == "world"
    visible = {t for t, c in three_d[0]["topics"].items() if c["visible"]}
    assert {"/arm/scene", "/scene/objects", "/scene/plan"} <= visible <= set(SPECS)
    assert all(SPECS[t].schema_name in ("foxglove.SceneUpdate", "foxglove.PoseInFrame")
               for t in visible)
    phase = [configs[p] for p in shown if p.startswith("StateTransitions!")]
    assert [p["value"] for p in phase[0]["paths"]][0] == "/control/phase.phase"
    plots = {configs[p]["title"]: [q["value"] for q in configs[p]["paths"]]
             for p in shown if p.startswith("Plot!")}
    tracking = next(v for k, v in plots.items() if k.startswith("Tracking"))
    timing = next(v for k, v in plots.items() if k.startswith("Loop timing"))
    assert {"/arm/configuration.measured[0].kappa",
            "/arm/configuration.commanded[0].kappa"} <= set(tracking)
    assert {"/control/loop_timing.period_ms", "/control/loop_timing.work_ms"} <= set(timing)
    logs = [configs[p] for p in shown if p.startswith("Log!")]
    assert SPECS[logs[0]["topicToRender"]].schema_name == "foxglove.Log"


@pytest.mark.parametrize("path", sorted({
    q["value"] for c in json.loads(LAYOUT.read_text())["configById"].values()
    for q in c.get("paths", [])}))
def test_every_plotted_path_is_a_field_lichtblick_knows(path: str) -> None:
    assert resolve(path) in ("float64", "string", "bool")


def test_resolve_refuses_a_wrong_path() -> None:
    with pytest.raises(AssertionError, match="has no field 'kapa'"):
        resolve("/arm/configuration.measured[0].kapa")
    with pytest.raises(AssertionError, match="index mismatch"):
        resolve("/arm/configuration.measured.kappa")
