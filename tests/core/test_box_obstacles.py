"""Box obstacles for the extensible arm: box distance, the tip IK and paths keeping the whole
body (``body_radius`` around the backbone) a set clearance from every box (checked by
independent dense forward kinematics), refusals that name the box, and the scene file round
trip."""

import json
import math

import numpy as np
import pytest

from core import robots
from core.kinematics import box_clearance as bc
from core.kinematics import delta as dk
from core.kinematics.delta_ik import solve_tip_ik
from core.planning import box_scene as bs
from core.planning.paths import BlockedPath, plan_path
from core.robot_sections import PathSettings

ARM = robots.load("extensible")
CLEARANCE = 0.02
COARSE = PathSettings(rate_hz=50.0, spacing=0.002)


def box_distance(points, lo, hi):
    """Independent signed distance: clip outside; inside, minus the nearest face's depth."""
    p = np.asarray(points, dtype=float)
    outside = np.linalg.norm(p - np.clip(p, lo, hi), axis=-1)
    depth = np.minimum(p - lo, hi - p).min(axis=-1)
    return np.where(outside > 0, outside, -depth)


def dense_backbone(delta, step=0.0005):
    """Backbone points every <= step along each segment, from delta.forward_kinematics on
    segments cut short (an arc fraction s of segment i is segment i with (s dx, s dy, s L))."""
    delta = np.asarray(delta, dtype=float)
    frames = dk.forward_kinematics(delta, ARM.L0, ARM.d)
    out = [np.zeros((1, 3))]
    for i, (dx, dy, dl) in enumerate(delta):
        length = ARM.L0 + dl
        s = np.linspace(0.0, 1.0, int(math.ceil(length / step)) + 1)[1:]
        part = np.stack([s * dx, s * dy, s * length - ARM.L0], axis=-1)
        T = frames[i] @ dk.segment_transform(part, ARM.L0, ARM.d)
        out.append(T[:, :3, 3])
    return np.vstack(out)


def min_distance(delta, boxes):
    """Distance of the arm's body surface (ARM.body_radius around the dense backbone)."""
    pts = dense_backbone(delta)
    return min(float(box_distance(pts, b.lo, b.hi).min()) for b in boxes) - ARM.body_radius


def test_signed_distance_matches_an_independent_formula_and_its_gradient():
    box = bc.make_box("B", (0.1, -0.05, 0.2), (0.1, 0.2, 0.04))
    pts = np.random.default_rng(3).uniform(-0.3, 0.4, (4000, 3))
    d, g = bc.signed_distance_and_gradient(pts, box)
    np.testing.assert_allclose(d, box_distance(pts, box.lo, box.hi), atol=1e-12)
    h = 1e-7
    fd = np.stack([(bc.signed_distance(pts + h * e, box) - bc.signed_distance(pts - h * e, box))
                   / (2 * h) for e in np.eye(3)], axis=-1)
    np.testing.assert_allclose(g, fd, atol=1e-5)


def test_backbone_samples_lie_on_the_forward_kinematics():
    delta = np.array([[0.03, -0.01, 0.12], [-0.02, 0.025, 0.2]])
    pts = bc.backbone_points(ARM, delta, 50)
    frames = dk.forward_kinematics(delta, ARM.L0, ARM.d)
    np.testing.assert_allclose(pts[50], frames[1, :3, 3], atol=1e-14)
    np.testing.assert_allclose(pts[100], frames[2, :3, 3], atol=1e-14)
    dense = dense_backbone(delta, step=1e-4)
    # every sample is on the independently sampled backbone (within its spacing)
    gaps = np.linalg.norm(pts[:, None] - dense[None], axis=-1).min(axis=1)
    assert gaps.max() < 1e-4


# A shelf board beside the arm; the target sits over it, high enough for the arm's body (45 mm
# radius) plus the clearance to reach over the board (at 60 mm above it, as before the body
# counted, the body would leave 15 mm < 20 mm).
SHELF = bc.make_box("Shelf", (0.20, 0.0, 0.25), (0.20, 0.30, 0.02))
OVER_SHELF = np.array([0.20, 0.0, 0.38])


def test_ik_reaches_over_a_shelf_edge_keeping_the_backbone_clear():
    free = solve_tip_ik(ARM, OVER_SHELF)
    assert free.reachable and min_distance(free.delta, [SHELF]) < 0  # the plain IK cuts through
    res = solve_tip_ik(ARM, OVER_SHELF, boxes=[SHELF], clearance=CLEARANCE)
    assert res.reachable and res.refusal == "" and res.clear
    assert np.linalg.norm(dk.tip_position(ARM, res.delta) - OVER_SHELF) <= 1e-3
    # independent dense check: every backbone point >= clearance (half the sampling step slack)
    assert min_distance(res.delta, [SHELF]) >= CLEARANCE - 2.5e-4
    assert np.all(res.lengths >= ARM.rack_min) and np.all(res.lengths <= ARM.rack_max)
    assert np.all(dk.bend_angles(res.delta, ARM.d) <= ARM.theta_max + 1e-12)


def drawer():
    """A drawer opening facing the arm (x 200-450 mm, z 60-220 mm inside: 160 mm tall, so the
    body's 45 mm radius and the 20 mm clearance fit above and below the target at z 140 mm):
    top and bottom boards, back wall and two sides."""
    return [bc.make_box("Top", (0.325, 0.0, 0.23), (0.25, 0.30, 0.02)),
            bc.make_box("Bottom", (0.325, 0.0, 0.05), (0.25, 0.30, 0.02)),
            bc.make_box("Back", (0.46, 0.0, 0.14), (0.02, 0.30, 0.20)),
            bc.make_box("Left", (0.325, 0.16, 0.14), (0.25, 0.02, 0.20)),
            bc.make_box("Right", (0.325, -0.16, 0.14), (0.25, 0.02, 0.20))]


def test_ik_reaches_into_a_drawer_opening_clear_of_every_wall():
    boxes = drawer()
    target = np.array([0.38, 0.0, 0.14])
    free = solve_tip_ik(ARM, target)
    assert free.reachable and min_distance(free.delta, boxes) < 0  # the single arc hits the top
    res = solve_tip_ik(ARM, target, boxes=boxes, clearance=CLEARANCE)
    assert res.reachable and res.clear, res.refusal
    assert np.linalg.norm(dk.tip_position(ARM, res.delta) - target) <= 1e-3
    assert min_distance(res.delta, boxes) >= CLEARANCE - 2.5e-4


def test_a_target_the_boxes_cut_off_is_refused_naming_the_box():
    ceiling = bc.make_box("Ceiling", (0.0, 0.0, 0.26), (2.0, 2.0, 0.02))
    res = solve_tip_ik(ARM, OVER_SHELF, boxes=[ceiling], clearance=CLEARANCE)
    assert not res.reachable and "Ceiling" in res.refusal
    # the answer is the closest collision-free posture: tip below the board, clear of it (the
    # tip's body too: at most 0.25 - clearance - body radius high)
    assert min_distance(res.delta, [ceiling]) >= CLEARANCE - 2.5e-4
    assert res.error >= OVER_SHELF[2] - (0.25 - CLEARANCE - ARM.body_radius) - 1e-3
    assert "mm" in res.refusal


def test_a_target_inside_or_too_near_a_box_is_refused():
    res = solve_tip_ik(ARM, [0.2, 0.0, 0.25], boxes=[SHELF], clearance=CLEARANCE)
    assert not res.reachable and "inside box 'Shelf'" in res.refusal
    res = solve_tip_ik(ARM, [0.2, 0.0, 0.27], boxes=[SHELF], clearance=CLEARANCE)
    assert not res.reachable and "10.0 mm from box 'Shelf'" in res.refusal
    # 60 mm from the board: the backbone would keep 20 mm, but the body keeps 60 - 45 = 15 mm
    res = solve_tip_ik(ARM, [0.2, 0.0, 0.32], boxes=[SHELF], clearance=CLEARANCE)
    assert not res.reachable and "would be 15.0 mm from it" in res.refusal


def test_ik_box_input_is_checked():
    with pytest.raises(ValueError, match="clearance"):
        solve_tip_ik(ARM, OVER_SHELF, boxes=[SHELF], clearance=-0.01)
    with pytest.raises(ValueError, match="clearance"):
        solve_tip_ik(ARM, OVER_SHELF, boxes=[SHELF], clearance=float("nan"))
    with pytest.raises(ValueError, match="unique"):
        solve_tip_ik(ARM, OVER_SHELF, boxes=[SHELF, SHELF], clearance=0.01)


# A post beside the straight arm (its near face 40 mm from the backbone: the body reaches 5 mm
# into it). Above the base, as before the body counted, no posture moving the tip across over
# it keeps the body 20 mm clear (the arm must cross the straight posture under it).
POST = bc.make_box("Post", (0.0, 0.06, 0.17), (0.04, 0.04, 0.04))
TRAVERSE = np.array([[-0.12, 0.0, 0.30], [0.12, 0.0, 0.30]])


def interpolated(lengths, parts=4):
    """The straight rack-space lines between samples, as the runner streams them."""
    L = np.asarray(lengths)
    f = (np.arange(parts) / parts)[None, :, None, None]
    out = (L[:-1, None] + (L[1:] - L[:-1])[:, None] * f).reshape(-1, *L.shape[1:])
    return np.vstack([out, L[-1:]])


def test_path_keeps_the_backbone_clear_of_a_box_between_its_points():
    free = plan_path(ARM, TRAVERSE, settings=COARSE)
    assert min(min_distance(d, [POST]) for d in free.deltas) < 0  # plain plan hits the post
    mp = plan_path(ARM, TRAVERSE, settings=COARSE, boxes=[POST], clearance=CLEARANCE)
    assert mp.max_error <= 1e-3 and mp.nearest_box == "Post"
    assert mp.clearance >= CLEARANCE
    lines = interpolated(mp.lengths)
    deltas = dk.delta_from_actuators(lines, ARM.phi, ARM.L0)
    worst = min(min_distance(d, [POST]) for d in deltas[::2])
    assert worst >= CLEARANCE - 2.5e-4


def test_path_through_a_box_is_refused_naming_it():
    with pytest.raises(BlockedPath, match="box 'Post'"):
        plan_path(ARM, [[-0.12, 0.06, 0.17], [0.12, 0.06, 0.17]], settings=COARSE,
                  boxes=[POST], clearance=CLEARANCE)


def test_scene_round_trip_and_bad_input():
    scene = bs.BoxScene((SHELF, POST), 0.015)
    assert bs.scene_from_json(bs.scene_to_json(scene)) == scene
    good = json.loads(bs.scene_to_json(scene))
    bad = [
        "not json", json.dumps({"objects": []}),
        json.dumps({**good, "boxes": [{"name": "A", "centre": [0, 0, 0.3], "size": [0.1, -0.1, 0.1]}]}),
        json.dumps({**good, "boxes": [{"name": "A", "centre": [0, float("nan"), 0.3],
                                        "size": [0.1, 0.1, 0.1]}]}),
        json.dumps({**good, "boxes": [{"name": "A", "centre": [0, 0, 0.0], "size": [0.1, 0.1, 0.1]}]}),
        json.dumps({**good, "boxes": [good["boxes"][0], good["boxes"][0]]}),
        json.dumps({**good, "clearance": -1}),
        json.dumps({**good, "boxes": [{"name": "A", "size": [0.1, 0.1, 0.1]}]}),
    ]
    for text in bad:
        with pytest.raises(ValueError):
            bs.scene_from_json(text)
    with pytest.raises(ValueError, match="contains the arm's base"):
        scene.with_box(bc.make_box("Base", (0, 0, 0), (0.1, 0.1, 0.1)))
    with pytest.raises(ValueError, match="closer than the clearance"):
        scene.with_box(bc.make_box("Low", (0, 0, 0.06), (0.1, 0.1, 0.1)))
    with pytest.raises(ValueError, match="exists"):
        scene.with_box(SHELF)
    assert scene.without("Post").names() == ["Shelf"]
    assert scene.free_name() == "Box 1"


def test_route_from_over_the_shelf_to_under_it_detours_clear_of_the_shelf():
    from core.planning.box_routes import reach_clear
    over = solve_tip_ik(ARM, OVER_SHELF, boxes=[SHELF], clearance=CLEARANCE)
    under = np.array([0.20, 0.0, 0.15])
    got = reach_clear(ARM, under, over.delta, restarts=True, settings=None, boxes=[SHELF],
                      clearance=CLEARANCE)
    assert got.refusal == "" and got.result.reachable and got.route is not None
    chain = np.stack([over.delta, *got.route.postures])
    np.testing.assert_allclose(chain[-1], got.result.delta)
    # the straight line is blocked, so this is a detour; every leg is clear when sampled densely
    direct = interpolated(dk.robot_rack_lengths(ARM, chain[[0, -1]]), parts=200)
    assert min(min_distance(d, [SHELF]) for d in dk.delta_from_actuators(
        direct, ARM.phi, ARM.L0)) < CLEARANCE
    assert len(chain) > 2
    legs = interpolated(dk.robot_rack_lengths(ARM, chain), parts=200)
    deltas = dk.delta_from_actuators(legs, ARM.phi, ARM.L0)
    assert min(min_distance(d, [SHELF]) for d in deltas) >= CLEARANCE - 2.5e-4
