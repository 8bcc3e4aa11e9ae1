"""The grasp layer's line and point nodes never reach a browser with points and colours of
different lengths.

viser sends a node's new points and new colours as two messages; a browser that draws between
them (the two may fall in different websocket windows) draws per-vertex colours of the wrong
length, seen as white lines at random (console/scene/carry_view.py first). Here every scene message
the plan layer queues is recorded and replayed onto each node's state as a browser would apply
it: after every single message, a node's colours are one uniform colour or as many as its
points. Plans of several objects in a row (different numbers of approach circles and
waypoints, failed circles, trails on and off) are drawn into one :class:`PlanScene`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from viser import _messages

from console.scene.plan_view import (
    CIRCLE_SEL_COLOR,
    GHOST_SEL_COLOR,
    PALM_COLOR,
    PlanScene,
    plan_geometry,
)
from core.planning.grasp import plan_grasp
from core.robots import load

ROBOT = load("soft-arm")
# Objects with 5, 12 (two failed circles), 9 (one failed) and 8 approach circles.
OBJECTS = [((-0.2, 0.2), 0.0165), ((0.25, 0.02), 0.02), ((0.3, 0.25), 0.03),
           ((-0.3, 0.1), 0.01)]


class BrowserNodes:
    """Each line-segments and point-cloud node's points and colours, as a browser holds them
    after applying one message at a time; every inconsistent moment is kept."""

    def __init__(self) -> None:
        self.nodes: dict[str, dict[str, Any]] = {}
        self.mismatches: list[str] = []

    def drawn(self, prefix: str) -> set[tuple]:
        """The (segment, colour) pairs the visible nodes named ``prefix``... draw."""
        return set().union(*(_drawn(n) for name, n in self.nodes.items()
                             if name.startswith(prefix) and n["visible"]))

    def apply(self, message: Any) -> None:
        if isinstance(message, (_messages.LineSegmentsMessage, _messages.PointCloudMessage)):
            self.nodes[message.name] = {"points": np.asarray(message.props.points),
                                        "colors": np.asarray(message.props.colors),
                                        "visible": True}
        elif isinstance(message, _messages.SetSceneNodeVisibilityMessage):
            if message.name in self.nodes:
                self.nodes[message.name]["visible"] = message.visible
            return
        elif isinstance(message, _messages.SceneNodeUpdateMessage) and message.name in self.nodes:
            for key in ("points", "colors"):
                if key in message.updates:
                    self.nodes[message.name][key] = np.asarray(message.updates[key])
        elif isinstance(message, _messages.RemoveSceneNodeMessage):
            self.nodes.pop(message.name, None)
        else:
            return
        node = self.nodes.get(message.name)
        if node is not None and node["colors"].size not in (3, node["points"].size):
            self.mismatches.append(f"{message.name}: {node['points'].shape[0]} points, "
                                   f"colours {node['colors'].shape}")


@pytest.fixture
def recorded(server: Any, monkeypatch: pytest.MonkeyPatch) -> BrowserNodes:
    browser = BrowserNodes()
    queue = server.scene._queue_scene_message

    def record(message: Any) -> None:
        browser.apply(message)
        queue(message)

    monkeypatch.setattr(server.scene, "_queue_scene_message", record)
    return browser


def _drawn(node: dict[str, Any]) -> set[tuple]:
    """The (segment, colour) pairs a node draws (padding copies draw nothing new)."""
    pts = np.round(np.asarray(node["points"], float).reshape(len(node["points"]), -1), 5)
    cols = np.asarray(node["colors"])
    cols = (np.broadcast_to(cols, np.asarray(node["points"]).shape) if cols.size == 3 else cols)
    cols = cols.reshape(len(pts), -1)
    return {(tuple(p), tuple(c)) for p, c in zip(pts, cols)}


def _expected(points: np.ndarray, colors: Any) -> set[tuple]:
    return _drawn({"points": np.asarray(points, np.float32),
                   "colors": np.asarray(colors, np.uint8)})


def test_plans_in_a_row_never_leave_a_node_with_points_and_colours_apart(
        server: Any, recorded: BrowserNodes) -> None:
    layer = PlanScene(server, ROBOT)
    plans = [plan_grasp(ROBOT, np.zeros(ROBOT.n_segments), c, r) for c, r in OBJECTS]
    assert len({len(p.radii) for p in plans}) == len(plans)     # every count differs
    assert not all(p.success for p in plans)                     # red circles among them
    shown = 0
    for plan in plans + plans[::-1]:
        for index, trail in ((plan.n - 1, True), (1, True), (0, False), (plan.n - 1, False)):
            layer.draw_plan(plan, index, trail)
            g = plan_geometry(ROBOT, plan, index, trail)
            # What the browser draws is the plan's geometry, whatever the nodes' sizes.
            assert recorded.drawn("/grasp/plan/circles") == _expected(g["circles"],
                                                                      g["circle_colors"])
            assert recorded.drawn("/grasp/plan/circle_sel") == _expected(g["circle_sel"],
                                                                         CIRCLE_SEL_COLOR)
            assert recorded.drawn("/grasp/plan/ghost_sel") == _expected(g["ghost_sel"],
                                                                        GHOST_SEL_COLOR)
            ghosts = recorded.drawn("/grasp/plan/ghosts")
            assert layer.ghosts.visible == (len(g["ghosts"]) > 0)
            if len(g["ghosts"]):
                shown += 1
                assert ghosts == _expected(g["ghosts"], g["ghost_colors"])
            else:
                assert ghosts == set()
            palms = recorded.nodes["/grasp/plan/palms"]
            np.testing.assert_allclose(np.asarray(palms["points"], float), g["palms"],
                                       atol=2e-4)               # (float16 in a point cloud)
            assert tuple(np.asarray(palms["colors"]).reshape(-1, 3)[0]) == PALM_COLOR
        layer.draw_plan(None, 0, False)
        assert not any(n["visible"] for name, n in recorded.nodes.items()
                       if name.startswith("/grasp/plan/"))
    assert shown > 0
    assert recorded.mismatches == []


def test_carries_of_every_length_and_a_growing_node_keep_points_and_colours_together(
        server: Any, recorded: BrowserNodes) -> None:
    """The carry layer (its target dots a point cloud of one colour) and a :class:`FixedLines`
    made again, larger, with colours of its own: the same rule, message by message."""
    import dataclasses

    from console.scene.carry_view import CarryLayer, carry_geometry
    from console.scene.line_nodes import FixedLines

    plan = plan_grasp(ROBOT, np.zeros(ROBOT.n_segments), *OBJECTS[0])
    carry_layer = CarryLayer(server, ROBOT)
    grasp = np.asarray(plan.kappas)[-1]
    for m in (1, 3, 9, 2):              # 9 targets: more than the nodes were made for
        carry = grasp + np.linspace(0.2, 1.0, m)[:, None] * (np.ones(ROBOT.n_segments) - grasp)
        with_carry = dataclasses.replace(plan, carry=carry)
        carry_layer.draw(with_carry)
        g = carry_geometry(ROBOT, with_carry)
        assert recorded.drawn("/grasp/plan/carry_path") == _expected(
            g["path"], np.broadcast_to(np.array((0, 135, 145), np.uint8), g["path"].shape))
        np.testing.assert_allclose(
            np.asarray(recorded.nodes["/grasp/plan/carry_targets"]["points"], float),
            g["targets"], atol=2e-4)
    lines = FixedLines(server.scene, "/test/lines", (1, 2, 3), 0.01, 2)
    rng = np.random.default_rng(0)
    for k in (1, 2, 5, 3, 11, 1):
        segments = rng.uniform(-1, 1, (k, 2, 3))
        colors = rng.integers(0, 256, (k, 2, 3), dtype=np.uint8)
        lines.show(segments, colors)
        assert recorded.drawn("/test/lines") == _expected(segments, colors)
    lines.hide()
    assert recorded.drawn("/test/lines") == set()
    assert recorded.mismatches == []
