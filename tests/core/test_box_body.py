"""The extensible arm's body in box clearance: every box distance is from the body's surface
(``[segments] body_radius`` around the backbone), not from the centre line.

Independent expectations: closed-form gaps of a straight arm (a vertical segment of known
length) to boxes beside and above it, minus the radius; a bent posture's distance by brute
force over an independently sampled backbone (``delta.forward_kinematics`` of segments cut
short); the robot file's default (the platform radius) and its refusal below the rack radius.
"""

import dataclasses
import math

import numpy as np
import pytest
from robot_files import SHIPPED, robot_copy

from core import robots
from core.kinematics import box_clearance as bc
from core.kinematics import delta as dk
from core.planning import box_scene as bs
from core.planning.paths import BlockedPath, plan_path
from core.robot_schema import tomllib
from core.robots import RobotFileError

ARM = robots.load("extensible")
R = ARM.body_radius
STRAIGHT = np.array([[0.0, 0.0, 0.15], [0.0, 0.0, 0.15]])  # two 200 mm segments: tip at z 400 mm


def test_the_body_radius_defaults_to_the_platform_radius_and_is_read_from_the_file(tmp_path):
    assert R == ARM.half_width == 0.045 and R >= ARM.rack_radius
    table = tomllib.loads((SHIPPED / "extensible.toml").read_text())
    del table["segments"]["body_radius"]
    assert robots.parse(table, "no-body.toml").body_radius == ARM.half_width
    wide = robots.load(str(robot_copy("extensible", tmp_path, {"segments.body_radius": 0.06})))
    assert wide.body_radius == 0.06 and wide.half_width == ARM.half_width
    thin = robot_copy("extensible", tmp_path, {"segments.body_radius": 0.02}, name="thin")
    with pytest.raises(RobotFileError, match=r"segments.body_radius: must be >= segments.rack_radius"):
        robots.load(str(thin))


@pytest.mark.parametrize("lo, hi, gap", [
    ((0.10, -0.10, 0.10), (0.20, 0.10, 0.30), 0.10),                      # beside: x face 100 mm
    ((-0.10, -0.10, 0.45), (0.10, 0.10, 0.50), 0.05),                     # above the tip: 50 mm
    ((0.06, 0.08, 0.50), (0.20, 0.20, 0.60), math.sqrt(0.06**2 + 0.08**2 + 0.10**2)),  # corner
])
def test_a_straight_arm_is_the_geometric_gap_minus_the_body_radius_from_a_box(lo, hi, gap):
    box = bc.make_box("B", (np.add(lo, hi) / 2).tolist(), np.subtract(hi, lo).tolist())
    found = bc.clearance_of(ARM, STRAIGHT, [box])
    assert found.distance == pytest.approx(gap - R, abs=1e-9)
    assert found.describe() == f"the arm passes {(gap - R) * 1e3:.1f} mm from box 'B'"
    # a straight rack-space line between two straight postures: the same closed form
    lines = dk.robot_rack_lengths(ARM, np.stack([STRAIGHT, STRAIGHT]))
    assert bc.motion_clearance(ARM, lines, [box]).distance == pytest.approx(gap - R, abs=1e-9)
    # a body radius of 60 mm (robot file) moves it by exactly the difference
    wide = dataclasses.replace(ARM, body_radius=0.06)
    assert bc.clearance_of(wide, STRAIGHT, [box]).distance == pytest.approx(gap - 0.06, abs=1e-9)


def test_a_box_the_backbone_clears_but_the_body_reaches_is_inside():
    box = bc.make_box("Near", (0.07, 0.0, 0.2), (0.06, 0.1, 0.1))        # face at x = 40 mm
    found = bc.clearance_of(ARM, STRAIGHT, [box])
    assert found.distance == pytest.approx(0.04 - R, abs=1e-9) and found.distance < 0
    assert found.describe() == "the arm enters box 'Near' (5.0 mm deep)"


def brute_force_backbone(delta, step=2e-4):
    """Backbone points every <= step, each segment cut short by forward kinematics."""
    frames = dk.forward_kinematics(delta, ARM.L0, ARM.d)
    out = [np.zeros((1, 3))]
    for i, (dx, dy, dl) in enumerate(delta):
        length = ARM.L0 + dl
        s = np.linspace(0.0, 1.0, math.ceil(length / step) + 1)[1:]
        part = np.stack([s * dx, s * dy, s * length - ARM.L0], axis=-1)
        out.append((frames[i] @ dk.segment_transform(part, ARM.L0, ARM.d))[:, :3, 3])
    return np.vstack(out)


def test_a_bent_posture_matches_brute_force_minus_the_radius():
    rng = np.random.default_rng(5)
    box = bc.make_box("Shelf", (0.15, 0.05, 0.25), (0.12, 0.2, 0.03))
    for _ in range(5):
        bend = rng.uniform(-1, 1, (2, 2)) * ARM.bend_max / math.sqrt(2)
        delta = np.column_stack([bend, rng.uniform(0.02, 0.3, 2)])
        pts = brute_force_backbone(delta)
        outside = np.linalg.norm(pts - np.clip(pts, box.lo, box.hi), axis=-1)
        depth = np.minimum(pts - box.lo, box.hi - pts).min(axis=-1)
        want = float(np.where(outside > 0, outside, -depth).min()) - R
        found = bc.clearance_of(ARM, delta, [box])
        # samples <= 1 mm apart: the sampled minimum is within 0.5 mm above the true one (the
        # brute force's own, 0.2 mm apart, within 0.1 mm)
        assert want - 1e-4 <= found.distance <= want + 5e-4
        # the reported point is a backbone point at that surface distance
        assert bc.surface_distance(ARM, found.point, box) == pytest.approx(found.distance)


def test_the_base_keep_out_counts_the_body():
    box = bc.make_box("Low", (0.0, 0.0, 0.075), (0.2, 0.2, 0.05))        # 50 mm above the base
    bc.check_box_for_base(box, 0.004, R)                                  # body keeps 5 mm
    with pytest.raises(ValueError, match=r"is 5.0 mm from the arm's body at its base, closer "
                                         r"than the clearance 10.0 mm"):
        bc.check_box_for_base(box, 0.01, R)
    touching = bc.make_box("Touch", (0.0, 0.0, 0.065), (0.2, 0.2, 0.05))  # 40 mm < 45 mm
    with pytest.raises(ValueError, match="touches the arm's body at its base"):
        bc.check_box_for_base(touching, 0.0, R)
    scene = bs.BoxScene((), 0.01, body_radius=R)
    with pytest.raises(ValueError, match="arm's body at its base"):
        scene.with_box(box)
    assert bs.BoxScene((), 0.01).with_box(box).names() == ["Low"]      # backbone alone: clear
    assert scene.with_clearance(0.004).with_box(box).body_radius == R   # edits keep the body
    text = bs.scene_to_json(bs.BoxScene((box,), 0.004))
    assert "body" not in text                                          # not part of the file
    with pytest.raises(ValueError, match="arm's body at its base"):
        bs.scene_from_json(text.replace("0.004", "0.01"), body_radius=R)


def test_a_path_tip_whose_body_reaches_a_box_is_refused():
    # the tip passes 40 mm under the board: the backbone would clear it, the body does not
    board = bc.make_box("Board", (0.0, 0.0, 0.45), (0.4, 0.4, 0.02))      # underside z 440 mm
    with pytest.raises(BlockedPath, match=r"40.0 mm \(the arm's body reaching into it\) from "
                                          r"box 'Board'"):
        plan_path(ARM, [[-0.05, 0.0, 0.40], [0.05, 0.0, 0.40]], boxes=[board], clearance=0.0)
