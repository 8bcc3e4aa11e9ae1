"""Simulated soft arm: first-order lag (closed form), limits, stick-slip, object, gripper, mocap."""

import math

import numpy as np
import pytest

from core import robots
from core.control.capture import INFEASIBLE, SUCCESS, CaptureModel, characterise
from core.control.fastkin import fit, fk, point_in_pose
from core.control.gripper import close_sweep
from core.control.sim import SoftArmSim
from core.kinematics.planar import fit_arm, forward_kinematics, sample_backbone

DT = 0.01


@pytest.fixture(scope="module")
def arm():
    return robots.load("soft-arm")


def quiet(arm, seed=0, **changes):
    sim = SoftArmSim(arm, seed=seed)
    sim.p = sim.p.replace(stall_rate_hz=0.0, mocap={"noise_m": 0.0, "object_noise_m": 0.0,
                                                   "occlusion_rate_hz": 0.0}, **changes)
    return sim


def demands_for(sim, kappa_ss, base=0.0):
    d = np.full(13, base)
    diff = np.asarray(kappa_ss) * sim.p.counts_per_kappa
    d[0:12:2] += np.maximum(diff, 0)
    d[1:12:2] += np.maximum(-diff, 0)
    return d


def test_first_order_lag_matches_closed_form(arm):
    sim = quiet(arm, cylinder_rate=1e9)  # pistons instantaneous: a pure lag remains
    target = np.array([0.0, 0.0, 4.0, -6.0, 2.0, 8.0])
    d = demands_for(sim, target)
    for k in range(1, 101):
        sim.step(d, DT)
        expect = target * (1 - math.exp(-k * DT / sim.p.tau_s))
        assert np.allclose(sim.kappa, expect, rtol=0, atol=1e-12)


def test_prepressure_shortens_the_time_constant(arm):
    sim = quiet(arm, cylinder_rate=1e9)
    target = np.full(6, 3.0)
    d = demands_for(sim, target, base=sim.p.prepressure_ref)  # full common-mode volume
    sim.step(d, 0.1)
    tau = sim.p.tau_s / (1 + sim.p.prepressure_stiffening)
    assert np.allclose(sim.kappa, 3.0 * (1 - math.exp(-0.1 / tau)))


def test_curvature_and_cylinder_limits(arm):
    sim = quiet(arm)
    d = np.zeros(13)
    d[4] = 1e6  # far beyond the cylinder range
    for _ in range(600):
        sim.step(d, DT)
    assert sim.cylinders[4] == sim.p.cylinder_max
    expected = min(sim.p.cylinder_max / sim.p.counts_per_kappa, arm.kappa_max)
    assert sim.kappa[2] == pytest.approx(expected, rel=1e-6)
    d[4] = 1e4
    d[5] = 0.0
    sim.p = sim.p.replace(cylinder_max=1e5)
    for _ in range(600):
        sim.step(d, DT)
    assert sim.kappa[2] == pytest.approx(arm.kappa_max)  # curvature saturates at kappa_max


def test_stick_slip_is_seeded_and_stalls_then_slips(arm):
    def run(seed):
        sim = SoftArmSim(arm, seed=seed)
        sim.p = sim.p.replace(stall_rate_hz=5.0, stall_duration_s=(0.3, 0.3), slip_overshoot=0.5,
                              mocap={"noise_m": 0.0, "occlusion_rate_hz": 0.0})
        d = demands_for(sim, np.full(6, 6.0))
        ks = []
        for _ in range(300):
            sim.step(d, DT)
            ks.append(sim.kappa.copy())
        return sim, np.array(ks)

    a, ka = run(1)
    b, kb = run(1)
    c, kc = run(2)
    assert np.array_equal(ka, kb) and a.stalls == b.stalls > 0
    assert not np.array_equal(ka, kc)
    # A stall freezes a driven segment for its whole duration (0.3 s = 30 ticks).
    still = np.abs(np.diff(ka, axis=0)) < 1e-15
    runs = [max((len(s) for s in "".join("1" if v else "0" for v in still[:, j]).split("0")), default=0)
            for j in range(6)]
    assert max(runs) >= 29
    # Slips overshoot the steady state by at most slip_overshoot of the built-up error.
    assert ka.max() > 6.0 + 1e-6
    assert ka.max() <= 6.0 * 1.5 + 1e-9


def test_capture_sweep_captures_inside_and_misses_outside(arm):
    sim = SoftArmSim(arm)
    geom = sim.geom
    model = CaptureModel.from_robot(arm)
    cx, cy = model.center
    inside = np.array([[cx, cy], [cx + 0.01, cy + 0.01], [cx - 0.01, cy]])
    outside = np.array([[cx, cy + 0.05], [-0.04, cy], [geom.length + 0.04, cy]])
    r_in = close_sweep(geom, inside, 0.0165)
    r_out = close_sweep(geom, outside, 0.0165)
    assert r_in.captured.all()
    assert not r_out.captured.any()
    # Beside or beyond the finger they stay put; above it the finger tip pushes it away.
    assert np.allclose(r_out.position[1:], outside[1:])
    c = np.array(model.center)
    assert np.hypot(*(r_out.position[0] - c)) >= np.hypot(*(outside[0] - c))


def test_characterisation_reproduces_the_papers_capture_region(arm):
    cmap = characterise(arm)  # 5 mm grid, the paper's 3.3 cm object
    half_gripper = arm.gripper.length / 2
    # "about half a gripper length in diameter" (the paper) - equal-area diameter within 30 %.
    assert 0.7 * half_gripper < cmap.equivalent_diameter() < 1.3 * half_gripper
    j = np.argmin(np.abs(cmap.ys - cmap.model.center[1]))
    i = np.argmin(np.abs(cmap.xs - cmap.model.center[0]))
    assert cmap.outcome[j, i] == SUCCESS  # the planner's aim point is captured
    assert cmap.model_agreement() > 0.8
    assert (cmap.outcome == INFEASIBLE).any() and (cmap.outcome == 0).any()


def test_characterisation_saves_and_loads(arm, tmp_path):
    cmap = characterise(arm, spacing=0.01)
    for name in ("map.json", "map.npz"):
        back = type(cmap).load(cmap.save(tmp_path / name))
        assert np.array_equal(back.outcome, cmap.outcome) and np.allclose(back.xs, cmap.xs)
        assert back.model == cmap.model
    svg = cmap.to_svg()
    assert svg.startswith("<svg") and svg.count("#1f5fd6") == cmap.successes


def test_gripper_captures_carries_and_releases(arm):
    sim = quiet(arm)
    tip = sim.tip_pose()
    aim = point_in_pose(tip, arm.gripper.w_off_along, 2 * arm.gripper.g_off + 0.0165)
    sim.place_object(*aim, 0.0165)
    d = sim.demands.copy()
    d[12] = sim.p.gripper.counts_closed
    for _ in range(100):
        sim.step(d, DT)
    assert sim.captured
    rel = np.array(sim.obj.grip)
    d2 = demands_for(sim, np.full(6, 3.0))
    d2[12] = d[12]
    for _ in range(200):
        sim.step(d2, DT)
    tip = sim.tip_pose()
    assert np.allclose(sim.obj.xy, point_in_pose(tip, *rel), atol=1e-9)  # carried rigidly
    d2[12] = 0.0
    for _ in range(100):
        sim.step(d2, DT)
    assert not sim.captured
    put_down = sim.obj.xy.copy()
    sim.step(d2, DT)
    assert np.allclose(sim.obj.xy, put_down)


def test_gripper_misses_an_object_outside_its_reach(arm):
    sim = quiet(arm)
    tip = sim.tip_pose()
    sim.place_object(*point_in_pose(tip, 0.05, 0.12), 0.0165)
    start = sim.obj.xy.copy()
    d = sim.demands.copy()
    d[12] = sim.p.gripper.counts_closed
    for _ in range(100):
        sim.step(d, DT)
    assert not sim.captured and np.allclose(sim.obj.xy, start)


def test_arm_pushes_the_object_and_never_passes_through_it(arm):
    sim = quiet(arm)
    sim.place_object(-0.005, 0.15, 0.0165)  # overlapping the straight arm: pushed out at once
    hw = sim.p.arm_half_width
    body = sample_backbone(sim.kappa, arm.lengths, 16, arm.base_pose)[:, :2]
    assert np.hypot(*(body - sim.obj.xy).T).min() >= 0.0165 + hw - 1e-3
    start = sim.obj.xy.copy()
    d = demands_for(sim, np.array([8.0, 4.0, 0, 0, 0, 0]))  # swing the arm left into it
    for _ in range(200):
        sim.step(d, DT)
        body = sample_backbone(sim.kappa, arm.lengths, 16, arm.base_pose)[:, :2]
        assert np.hypot(*(body - sim.obj.xy).T).min() >= 0.0165 + hw - 2e-3
    assert np.hypot(*(sim.obj.xy - start)) > 0.02


def test_mocap_noise_occlusion_and_seed(arm):
    sim = SoftArmSim(arm, seed=3)
    sim.p = sim.p.replace(mocap={"noise_m": 0.0005, "occlusion_rate_hz": 0.0})
    truth = sim.shape()[1:, :2]
    err = np.array([sim.measure().markers - truth for _ in range(2000)])
    assert np.std(err) == pytest.approx(0.0005, rel=0.05)
    sim = SoftArmSim(arm, seed=3)
    sim.p = sim.p.replace(mocap={"occlusion_rate_hz": 5.0, "occlusion_duration_s": (0.05, 0.05)})
    hidden = []
    for _ in range(500):
        sim.step(sim.demands, DT)
        m = sim.measure()
        hidden.append(np.isnan(m.markers[:, 0]))
    hidden = np.array(hidden)
    assert hidden.any() and not hidden.all(axis=0).any()
    again = SoftArmSim(arm, seed=3)
    again.p = sim.p
    for i in range(50):
        again.step(again.demands, DT)
        assert np.array_equal(np.isnan(again.measure().markers[:, 0]), hidden[i])


def test_fast_kinematics_equal_the_reference(arm):
    rng = np.random.default_rng(0)
    for _ in range(20):
        k = rng.uniform(-arm.kappa_max, arm.kappa_max, 6)
        ends = fk(k, arm.lengths, arm.base_pose)
        assert np.allclose(ends, forward_kinematics(k, arm.lengths, arm.base_pose), atol=1e-12)
        k1, l1 = fit(ends[1:, :2], arm.base_pose)
        k2, l2 = fit_arm(ends[1:, :2], arm.base_pose)
        assert np.allclose(k1, k2, atol=1e-9) and np.allclose(l1, l2, atol=1e-12)
        assert np.allclose(k1, k, atol=1e-7)
