"""Skinned arm drawing: the client's linear blend skinning of the bone poses lands on today's
vertex geometry at full bend (both arms), and the dead band sends nothing for sub-band noise."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import pytest
import viser

from console.scene.arm_view_factory import make_arm_view
from console.scene.dead_band import DeadBand
from console.scene.extensible_arm_view import ExtensibleArmView
from console.core.model import model_for
from console.scene.soft_arm_view import SoftArmView
from console.scene.skin import TubeSkin, bspline_weights
from core.robots import load

SOFT = load("soft-arm")
EXT = load("extensible")
KMAX = 16.7  # 1/m, the soft arm's kappa_max
# 1/m rms per segment: the soft arm's measured curvatures, armed and holding on the simulator
# (its motion capture's 0.2 mm marker noise).
SOFT_KAPPA_NOISE = np.array([0.035, 0.11, 0.19, 0.25, 0.31, 0.35])



def skinned(handle, vertices, weights, bind, poses: np.ndarray):
    """What the browser draws: three.js v' = sum_i w_i B_i B_i,bind^-1 v, with the bone
    poses the handle last sent (each vertex has at most four weights: all viser sends)."""
    assert np.count_nonzero(weights, axis=1).max() <= 4
    sent = np.array([np.concatenate([b.wxyz, b.position]) for b in handle.bones])
    np.testing.assert_allclose(sent[:, 4:], poses[:, :3, 3], atol=2.0**-16)
    return TubeSkin.deform(vertices, weights, bind, poses)


def test_bspline_weights_are_a_partition_of_unity_and_reproduce_linear_functions() -> None:
    u = np.linspace(0.0, 6.0, 101)
    idx, w = bspline_weights(u, 7)
    np.testing.assert_allclose(w.sum(1), 1.0, atol=1e-12)
    knot = idx - 1  # bone b sits on knot b - 1
    np.testing.assert_allclose((w * knot).sum(1), u, atol=1e-12)
    assert idx.min() == 0 and idx.max() == 8
    with pytest.raises(ValueError):
        bspline_weights([7.5], 7)


@pytest.mark.parametrize("kappa", [np.full(6, KMAX), np.full(6, -KMAX),
                                   np.array([KMAX, KMAX, KMAX, -KMAX, -KMAX, -KMAX]),
                                   np.array([KMAX, -KMAX, KMAX, -KMAX, KMAX, -KMAX])])
def test_soft_arm_skinned_body_matches_the_vertex_mesh_at_full_bend(server, kappa) -> None:
    view = make_arm_view(server.scene, model_for(SOFT))
    assert isinstance(view, SoftArmView) and view.method == "skinned"
    assert view.update(kappa)
    want = view.geometry(kappa)["body"].astype(float)
    got = skinned(view.body, *view.skin.bind(view.body_topology, [0], view.radius),
                  view.skin.bind_poses(), view.skin.bone_poses(view.frames(kappa)))
    err = np.linalg.norm(got - want, axis=1)
    same_sign = np.all(kappa == kappa[0])
    # Constant curvature: only the blend's ~1 % ring shrink remains; where the curvature
    # flips sign the C2 skin rounds the corner by at most a tenth of the radius.
    assert err.max() < (0.3e-3 if same_sign else 0.1 * view.radius), err.max()
    # The tip ring (where the gripper attaches) stays put.
    tip = want[: view.body_topology.n_rings * view.sides][-view.sides:].mean(0)
    got_tip = got[: view.body_topology.n_rings * view.sides][-view.sides:].mean(0)
    assert np.linalg.norm(got_tip - tip) < 0.1e-3
    # Rings, gripper and palm: poses of the same geometry as the vertex method's.
    ends = view.frames(kappa)[view.samples_per_segment::view.samples_per_segment]
    np.testing.assert_allclose(view.rings.batched_positions, ends[:, :3, 3], atol=1e-6)
    np.testing.assert_allclose(view.palm.position, view.geometry(kappa)["palm"], atol=1e-9)
    g = view.geometry(kappa)["gripper"].astype(float)[: 2 * view.sides]
    far = g[view.sides:].mean(0)
    local_far = np.array([0.0, 0.0, SOFT.gripper.length])
    rot = ends[-1, :3, :3]
    np.testing.assert_allclose(view.gripper.position + rot @ local_far, far, atol=1e-6)


@pytest.mark.parametrize("q", [
    np.array([[0.03 * np.pi / 2, 0.0, 0.36], [0.0, -0.03 * np.pi / 2, 0.36]]),  # 90 deg each
    np.array([[0.0, 0.03 * np.pi / 2, 0.0], [0.03 * np.pi / 2, 0.0, 0.0]]),  # retracted
    np.array([[-0.03 * np.pi / 2, 0.0, 0.2], [0.03 * np.pi / 2, 0.0, 0.05]]),  # S-bend
])
def test_extensible_arm_skinned_backbone_and_racks_match_the_vertex_mesh(server, q) -> None:
    view = make_arm_view(server.scene, model_for(EXT))
    assert isinstance(view, ExtensibleArmView)
    assert np.allclose(np.linalg.norm(q[:, :2], axis=1) / EXT.d, np.pi / 2)  # full bend
    view.update(q)
    g = view.geometry(q)
    frames = view.frames(q)
    n, s = EXT.n_segments, view.samples_per_segment
    got = skinned(view.backbone,
                  *view.skin.bind_segments(view.backbone_topology, n, view.backbone_radius),
                  view.skin.bone_poses_segments(frames, n))
    assert np.linalg.norm(got - g["backbone"], axis=1).max() < 0.3e-3
    bind = view.skin.bind_each(view.rack_topology, view.rack_radius)
    for j, handle in enumerate(view.racks):
        got = skinned(handle, *bind, view.rack_bone_poses(frames, j))
        assert np.linalg.norm(got - g["racks"][j], axis=1).max() < 0.3e-3
    np.testing.assert_allclose(view.tip.position, g["tip_position"], atol=1e-9)
    assert len(view.platforms.batched_positions) == n + 1


def count_scene_messages(server: viser.ViserServer) -> list[object]:
    """Every scene message the server queues from now on (wraps viser's one queue entry)."""
    sent: list[object] = []
    api = server.scene
    original = api._queue_scene_message

    def record(message):  # type: ignore[no-untyped-def]
        sent.append(message)
        return original(message)

    api._queue_scene_message = record  # type: ignore[method-assign]
    return sent


@pytest.mark.parametrize("robot, method", [(SOFT, "skinned"), (EXT, "skinned"),
                                           (SOFT, "vertices"), (EXT, "vertices")])
def test_noise_below_the_dead_band_sends_nothing_and_a_move_above_it_sends(
        server, robot, method) -> None:
    model = model_for(robot)
    band = DeadBand(2e-4, np.deg2rad(0.1), settle_s=0.0)  # a band alone, no averaging
    view = make_arm_view(server.scene, model, method=method, dead_band=band)
    q = np.asarray(model.zero(), dtype=float) + 0.5 * (
        np.array([8.0, -5.0, 3.0, 0.0, 2.0, -1.0]) if robot is SOFT
        else np.array([[0.01, 0.0, 0.1], [0.0, 0.01, 0.05]]))
    assert view.update(q)
    sent = count_scene_messages(server)
    rng = np.random.default_rng(1)
    # Noise whose largest effect on any drawn frame stays inside the band.
    scale = 1e-3 if robot is SOFT else 2e-6  # 1/m of curvature, m of rack length
    for _ in range(50):
        noisy = q + scale * rng.uniform(-1, 1, np.shape(q))
        assert not band.moved(view.frames(q), view.frames(noisy))
        assert view.update(noisy) is False
    assert sent == []
    bigger = q + (0.2 if robot is SOFT else 2e-4)  # moves the tip by millimetres
    assert band.moved(view.frames(q), view.frames(bigger))
    assert view.update(bigger) is True
    assert len(sent) > 0


@pytest.mark.parametrize("robot, method", [(SOFT, "skinned"), (EXT, "skinned"),
                                           (SOFT, "vertices"), (EXT, "vertices")])
def test_an_arm_that_stops_inside_the_band_is_drawn_where_it_stopped(server, robot,
                                                                     method) -> None:
    """A source that keeps reporting the same state never lets the display go idle: the last
    small step (inside the band) is drawn once the state repeats, and only once."""
    model = model_for(robot)
    view = make_arm_view(server.scene, model, method=method,
                         dead_band=DeadBand(5e-4, np.deg2rad(0.5), settle_s=0.0))
    q = np.asarray(model.zero(), dtype=float) + (0.5 if robot is SOFT else 0.01)
    assert view.update(q)
    step = q + (2e-3 if robot is SOFT else 5e-6)  # far less than the band moves the tip
    assert not view.dead_band.moved(view.frames(q), view.frames(step))
    assert view.update(step) is False  # a small step on the way: held back
    assert view.update(step) is True  # the same state again: it stopped there, draw it
    sent = count_scene_messages(server)
    for _ in range(5):
        assert view.update(step) is False  # already drawn: nothing more
    assert sent == []


def test_averaged_dead_band_holds_a_noisy_still_arm_and_follows_a_move(server, monkeypatch,
                                                                      ) -> None:
    """Noise that crosses the band frame by frame (the soft arm's mocap in the simulator: a few
    mm at the gripper's end) averages out: after the first seconds (their first steps read as
    steady) a still arm is drawn a few times a minute, not 20 times a second (issue 29: 40 a
    minute with the band before); a clean move is drawn frame by frame; a state held back is
    drawn exactly when the display goes idle."""
    import console.scene.arm_view as arm_view

    clock = [100.0]
    monkeypatch.setattr(arm_view.time, "monotonic", lambda: clock[0])
    model = model_for(SOFT)
    view = make_arm_view(server.scene, model)
    band = view.dead_band
    assert band == DeadBand(1e-3, np.deg2rad(1.0), 4.0)
    q = np.array([8.0, -5.0, 3.0, 0.0, 2.0, -1.0])
    clock[0] += 5.0
    assert view.update(q)
    rng = np.random.default_rng(2)
    sigma = SOFT_KAPPA_NOISE
    frames = []
    for k in range(1300):  # 65 s at 20 frames/s
        if k == 100:
            sent_before = view.frames_sent
        clock[0] += 0.05
        noisy = q + sigma * rng.standard_normal(6)
        frames.append(view.frames(noisy))
        view.update(noisy)
    # The noise alone crosses the band in most frames ...
    crossing = np.mean([band.moved(view.frames(q), f) for f in frames])
    assert crossing > 0.8
    # ... but over the last minute a few frames are sent instead of 1200.
    assert view.frames_sent - sent_before <= 6
    # A clean move at ~14 mm/s of the tip (0.7 mm a frame) after a pause: every frame once it
    # is known to move (``moving_steps``), before that at least every other one (the still
    # band; tests/console/test_viewer_pacing.py bounds how far behind).
    clock[0] += 5.0
    start = view.frames_sent
    for k in range(1, 21):
        clock[0] += 0.05
        drawn = view.update(q + 0.01 * k)
        assert drawn or k < band.moving_steps
    assert view.frames_sent - start >= 20 - band.moving_steps // 2
    # A tiny last step is held back, then drawn exactly when the display goes idle.
    clock[0] += 0.05
    last = q + 0.01 * 20 + 1e-3
    assert view.update(last) is False
    assert view.flush() is True
    assert view.flush() is False
    np.testing.assert_allclose(view.palm.position, view.geometry(last)["palm"], atol=1e-9)


@pytest.mark.parametrize("seed", [0, 1])
def test_an_armed_soft_arm_holding_in_the_closed_loop_simulator_is_drawn_about_never(
        server, monkeypatch, seed) -> None:
    """The soft arm armed and holding in core's control cycle (``SimLoop``: the controller acts
    on the simulated motion capture's noise, so the measured curvatures jitter with correlated
    steps, lag-1 ~0.25, as on the emulator): its view at the console's 30 states/s draws at
    most one frame in 2.5 minutes. Steadiness over 0.25 s read that noise as a steady move
    a few times a minute (the moving band drew it: 1-3 frames/min here, ~4 on the emulator,
    each costing a software-rendered page ~1 s of redraws; issue 29)."""
    import console.scene.arm_view as arm_view
    from holding_arm import holding_kappa

    clock = [100.0]
    monkeypatch.setattr(arm_view.time, "monotonic", lambda: clock[0])
    view = make_arm_view(server.scene, model_for(SOFT))
    q, armed = holding_kappa(SOFT, seed, 3 * 60.0)  # 3 minutes; a state every third tick
    assert armed
    assert np.all(q[300:].std(axis=0) > 0.5 * SOFT_KAPPA_NOISE)  # the noise is there
    for i, kappa in enumerate(q):
        if i == 1000:  # after the first 30 s
            sent = view.frames_sent
        clock[0] += 0.03
        view.update(kappa)
    assert view.frames_sent - sent <= 1


def test_dead_band_measures_translation_and_rotation() -> None:
    band = DeadBand(2e-4, np.deg2rad(0.1))
    a = np.tile(np.eye(4), (3, 1, 1))
    b = a.copy()
    b[1, 0, 3] = 1.9e-4
    assert not band.moved(a, b)
    b[1, 0, 3] = 2.1e-4
    assert band.moved(a, b)
    for angle, expected in ((np.deg2rad(0.09), False), (np.deg2rad(0.11), True)):
        c = a.copy()
        c[2, :2, :2] = [[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]]
        assert band.moved(a, c) is expected


def test_unknown_method_is_refused(server) -> None:
    with pytest.raises(ValueError, match="method"):
        make_arm_view(server.scene, model_for(SOFT), method="pixels")  # type: ignore[arg-type]


def test_console_renders_the_skinned_arm_by_moving_the_same_bones(server) -> None:
    from console.app import ConsoleApp

    app = ConsoleApp(EXT, server)
    view = app.view
    assert isinstance(view, ExtensibleArmView) and view.method == "skinned"
    handles = (view.backbone, *view.racks, view.platforms, view.tip)
    vertices = view.backbone.vertices.copy()  # the bind pose, sent once
    with app:
        q = np.array([[0.02, 0.0, 0.15], [0.0, 0.0, 0.1]])
        state = app.store.request(q, "test")
        deadline = time.monotonic() + 3.0
        while app.last_drawn_seq != state.seq:
            assert time.monotonic() < deadline, "not drawn"
            time.sleep(0.01)
    assert (view.backbone, *view.racks, view.platforms, view.tip) == handles
    np.testing.assert_array_equal(view.backbone.vertices, vertices)
    poses = view.skin.bone_poses_segments(view.frames(q), EXT.n_segments)
    got = np.array([b.position for b in view.backbone.bones])
    np.testing.assert_allclose(got, poses[:, :3, 3], atol=2.0**-16)
    np.testing.assert_allclose(view.tip.position, view.geometry(q)["tip_position"], atol=1e-9)


def test_tubes_posed_together_get_each_tube_s_own_bone_poses(server) -> None:
    """The extensible view poses its backbone and racks in one vectorised call: every tube's
    bones are those it gets alone, and the racks' handles hold them after a frame."""
    view = make_arm_view(server.scene, model_for(EXT), dead_band=None)
    q = np.array([[0.03, -0.01, 0.12], [-0.02, 0.025, 0.08]])
    frames = view.frames(q)
    tubes = np.stack([frames, *(view.rack_frames(frames, j) for j in range(3))])
    together = view.skin.bone_poses_segments(tubes, EXT.n_segments)
    alone = [view.skin.bone_poses_segments(t, EXT.n_segments) for t in tubes]
    np.testing.assert_allclose(together, np.stack(alone), atol=1e-12)
    view.update(q)
    for j, handle in enumerate(view.racks):
        got = np.array([b.position for b in handle.bones])
        np.testing.assert_allclose(got, view.rack_bone_poses(frames, j)[:, :3, 3],
                                   atol=2.0**-16)


def test_readout_follows_the_drawn_arm_at_a_readable_rate_and_catches_up_when_idle(
        server) -> None:
    from console.app import ConsoleApp
    from console.panels.common.readout import READOUT_HZ, ReadoutPanel

    now = [100.0]  # a simulated clock: the readout's rate limit must not hang on the CPU
    app = ConsoleApp(SOFT, server, clock=lambda: now[0])
    readout = app.panel(ReadoutPanel)
    q = np.array([8.0, -5.0, 3.0, 0.0, 2.0, -1.0])
    first = app.store.request(q, "test")
    app.render(first)
    shown = readout.html.content
    assert app.view.frames_sent >= 2 and shown
    # Sub-band noise: nothing drawn, the readout stays as it was.
    for k in range(5):
        app.render(app.store.report(q + 1e-4 * (k + 1), "mocap"))
    assert readout.html.content == shown
    # Two moves within 1 / READOUT_HZ: the second is held back ...
    now[0] += 1.1 / READOUT_HZ
    moved = app.store.report(q + 0.5, "mocap")
    app.render(moved)
    after_first_move = readout.html.content
    assert after_first_move != shown
    now[0] += 0.9 / READOUT_HZ
    last = app.store.report(q + 1.0, "mocap")
    app.render(last)
    assert readout.html.content == after_first_move
    # ... and shown once the display goes idle.
    app._idle()
    assert f"#{last.seq}" in readout.source.content
    assert readout.html.content == readout._render(last)


def test_a_short_pause_of_a_noisy_source_draws_nothing_a_quiet_one_draws_what_was_held(
        server) -> None:
    """The display without a new state for less than FLUSH_IDLE_S (an armed soft arm's view
    pauses 0.2-0.3 s a few times a minute while it keeps reporting noise) draws nothing; once
    the source has been quiet that long, the state the dead band held back is drawn."""
    from console.app import FLUSH_IDLE_S, ConsoleApp

    app = ConsoleApp(SOFT, server)
    q = np.array([8.0, -5.0, 3.0, 0.0, 2.0, -1.0])
    app.render(app.store.request(q, "test"))
    noisy = q + 0.005  # inside the band: held back
    assert not app.view.dead_band.moved(app.view.frames(q), app.view.frames(noisy))
    app.render(app.store.report(noisy, "mocap"))
    sent = app.view.frames_sent
    for idle_s in (0.2, 0.4, 0.6, FLUSH_IDLE_S - 0.01):
        app._idle(idle_s)
    assert app.view.frames_sent == sent
    np.testing.assert_allclose(app.view.palm.position, app.view.geometry(q)["palm"], atol=1e-9)
    app._idle(FLUSH_IDLE_S)
    assert app.view.frames_sent == sent + 1
    np.testing.assert_allclose(app.view.palm.position, app.view.geometry(noisy)["palm"],
                               atol=1e-9)


def test_plot_columns_are_thinned_to_float32_keeping_the_newest_sample() -> None:
    from console.panels.common.plot_data import thin

    t = np.arange(1000) * 0.01
    y = np.sin(t)
    tt, yy = thin((t, y), 100)
    assert len(tt) <= 100 and tt.dtype == np.float32 and yy.dtype == np.float32
    assert tt[-1] == np.float32(t[-1]) and np.all(np.diff(tt) > 0)
    np.testing.assert_allclose(yy, np.sin(tt.astype(float)), atol=1e-5)  # samples, not means
    short = thin((t[:50], y[:50]), 100)
    np.testing.assert_array_equal(short[0], t[:50].astype(np.float32))
    with pytest.raises(ValueError):
        thin((t, y[:-1]))


def test_steadiness_reads_a_clean_move_after_a_pause_as_steady_and_noise_as_not() -> None:
    """|mean step| / mean |step|: ~1 for a move, ~sqrt(dt / 2 tau) for noise (independent
    steps: 0.32 at dt = 0.05 s, tau = 0.25 s). A pause starts it afresh from the frames that
    end it: the step across the pause (here from a frame 3 mm off) is no move's step."""
    from console.scene.dead_band import Steadiness

    rng = np.random.default_rng(4)
    st = Steadiness(tau=0.25)
    noise = [st.update(_at(1e-3 * rng.standard_normal((3, 3))), 0.05) for _ in range(400)]
    assert 0.1 < np.median(noise[50:]) < 0.45
    st.update(_at(np.full((3, 3), 3e-3)), 0.05)  # the last frame before the pause
    move = [st.update(_at(np.full((3, 3), 7e-4 * k)), 2.0 if k == 0 else 0.05)
            for k in range(20)]
    assert move[0] == 1.0 and st.steps == 19  # (the pause's end starts afresh)
    assert min(move) > 0.99


def _at(points: np.ndarray) -> np.ndarray:
    """(P, 4, 4) identity frames at ``points`` (P, 3)."""
    f = np.tile(np.eye(4), (len(points), 1, 1))
    f[:, :3, 3] = points
    return f


@pytest.mark.parametrize("robot", ["soft-arm", "extensible"])
def test_a_noisy_arm_that_jumped_and_stands_still_is_drawn_as_after_a_fresh_start(
        server, monkeypatch, robot) -> None:
    """A jump (a replay seek, a device connecting) to a pose where the arm then stands still,
    measured with noise: drawn at the jump and afterwards as often as by a view that started
    there (the same noise). The average used to catch up from the old pose (a frame every
    0.4-3 s for ~10 s) and the jump's one step read as a steady move for ~2 s (every noisy frame
    drawn: 76 frames in 12 s for the soft arm); the extensible still row of
    ``benchmarks/bench_viewers.py`` measured 1.0 frame/s. Simulated clock, 30 frames/s."""
    import console.scene.arm_view as arm_view

    clock = [100.0]
    monkeypatch.setattr(arm_view.time, "monotonic", lambda: clock[0])
    model = model_for(SOFT if robot == "soft-arm" else EXT)
    rng = np.random.default_rng(5)
    if robot == "soft-arm":
        start = np.zeros(6)
        still = np.array([8.0, -5.0, 3.0, 0.0, 2.0, -1.0])
        sigma = SOFT_KAPPA_NOISE
    else:
        start = np.zeros(model.shape)
        still = np.zeros(model.shape)
        still[:, 2] = 0.5 * (EXT.rack_min + EXT.rack_max) - EXT.L0
        still[0, 0], still[1, 1] = 0.015, -0.012
        sigma = 2e-5  # m: the drawn tip moves by ~0.05 mm rms (bench_viewers' noise)
    noise = sigma * rng.standard_normal((150 + 1 + 360, *start.shape))

    def drawn_after(view: Any, frames: list[np.ndarray]) -> int:
        sent = view.frames_sent
        for q in frames:  # 12 s at 30 frames/s
            clock[0] += 1 / 30
            view.update(q)
        return view.frames_sent - sent

    jumped = make_arm_view(server.scene, model)
    for k in range(150):  # 5 s standing at the start pose
        clock[0] += 1 / 30
        jumped.update(start + noise[k])
    assert np.linalg.norm(jumped.frames(still)[-1, :3, 3] - jumped.frames(start)[-1, :3, 3]) > 0.05
    clock[0] += 1 / 30
    assert jumped.update(still + noise[150])  # the jump is drawn
    after_jump = drawn_after(jumped, [still + n for n in noise[151:]])
    fresh = make_arm_view(server.scene, model, root="/fresh")
    clock[0] += 10.0
    assert fresh.update(still + noise[150])
    after_start = drawn_after(fresh, [still + n for n in noise[151:]])
    assert after_jump <= after_start + 1, (after_jump, after_start)
    assert after_start <= 6
