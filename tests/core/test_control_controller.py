"""Curvature controller: step response, anti-windup, pre-pressurisation, bad input."""

import dataclasses

import numpy as np
import pytest

from core import robots
from core.control.controller import CurvatureController
from core.control.params import ControllerParams
from core.control.sim import SoftArmSim

DT = 0.01


@pytest.fixture(scope="module")
def arm():
    return robots.load("soft-arm")


def quiet_sim(arm, **changes):
    """The simulated plant without stick-slip, noise or occlusion (a clean lag + gain error)."""
    sim = SoftArmSim(arm, seed=0)
    sim.p = sim.p.replace(stall_rate_hz=0.0, mocap={"noise_m": 0.0, "occlusion_rate_hz": 0.0},
                          **changes)
    return sim


def run(ctrl, sim, target, seconds):
    ks = []
    for _ in range(round(seconds / DT)):
        sim.step(ctrl.step(target, sim.kappa, DT).commands, DT)
        ks.append(sim.kappa.copy())
    return np.array(ks)


def test_step_response_converges_without_overshoot(arm):
    sim = quiet_sim(arm)
    # The plant gain is 10 % off the controller's model: only integral action removes the error.
    assert sim.p.counts_per_kappa != ControllerParams.from_robot(arm).counts_per_kappa
    ctrl = CurvatureController.from_robot(arm)
    ctrl.reset(sim.cylinders)
    run(ctrl, sim, np.zeros(6), 0.5)
    target = np.array([5.0, -5.0, 8.0, -3.0, 10.0, 12.0])
    ks = run(ctrl, sim, target, 4.0)
    assert np.abs(ks[-1] - target).max() < 0.01
    # Overshoot beyond the target, as a fraction of the step, stays under 3 %.
    past = np.maximum((ks - target) * np.sign(target), 0.0).max(axis=0) / np.abs(target)
    assert past.max() < 0.03
    # Feed-forward toward the plant's steady state: never moves the wrong way.
    assert np.all(ks * np.sign(target) > -0.05)
    # Within 5 % of the step after 1 s (plant lag 0.25 s, slew 2000 counts/s).
    assert np.all(np.abs(ks[100:] - target) <= 0.05 * np.abs(target))


def naive_pi_step(p, integ, target, meas, prev_cmd, dt):
    """Textbook PI + feed-forward with the same gains and limits but no anti-windup."""
    e = target - meas
    integ = integ + p.ki * e * dt
    u = p.counts_per_kappa * target + p.kp * e + integ
    span = p.cylinder_max - p.prepressure
    u = np.clip(u, -span, span)
    want = prev_cmd.copy()
    want[0:12:2] = p.prepressure + np.maximum(u, 0)
    want[1:12:2] = p.prepressure + np.maximum(-u, 0)
    slew = p.cylinder_rate * dt
    return integ, prev_cmd + np.clip(want - prev_cmd, -slew, slew)


def recovery_time(ks, target, tol=0.5):
    off = np.flatnonzero(np.abs(ks[:, 0] - target[0]) > tol)
    return (off.max() + 1) * DT if off.size else 0.0


def test_anti_windup_saturated_actuator_recovers_quickly(arm):
    p = ControllerParams.from_robot(arm)
    unreachable = np.full(6, 17.5)  # beyond what full cylinders give (and beyond kappa_max)
    back = np.full(6, 6.0)

    sim = quiet_sim(arm)
    ctrl = CurvatureController(p, 6, 6)  # all segments pre-pressurised: one span for all
    ctrl.reset(sim.cylinders)
    run(ctrl, sim, np.zeros(6), 0.5)
    saturated = run(ctrl, sim, unreachable, 3.0)
    assert ctrl.commands[0] == pytest.approx(p.cylinder_max)  # the actuator really saturated
    assert np.all(np.abs(ctrl.integrator) < 0.5 * p.ki)  # did not integrate 3 s of error
    assert saturated[-1, 0] < unreachable[0]
    ks = run(ctrl, sim, back, 3.0)
    t_aw = recovery_time(ks, back)

    # The same loop without anti-windup (independent textbook implementation).
    sim2 = quiet_sim(arm)
    cmd = sim2.cylinders.copy()
    integ = np.zeros(6)
    for target, seconds in ((np.zeros(6), 0.5), (unreachable, 3.0)):
        for _ in range(round(seconds / DT)):
            integ, cmd = naive_pi_step(p, integ, target, sim2.kappa, cmd, DT)
            sim2.step(cmd, DT)
    ks2 = []
    for _ in range(300):
        integ, cmd = naive_pi_step(p, integ, back, sim2.kappa, cmd, DT)
        sim2.step(cmd, DT)
        ks2.append(sim2.kappa.copy())
    t_naive = recovery_time(np.array(ks2), back)
    assert t_aw < 1.0
    assert t_naive > 2 * t_aw


def test_prepressurisation_of_both_root_channels(arm):
    p = ControllerParams.from_robot(arm)
    ctrl = CurvatureController.from_robot(arm)
    ctrl.reset()  # cylinders at their minimum
    assert not ctrl.prepressurised
    steps = int(np.ceil(p.prepressure / (p.cylinder_rate * DT)))
    for _ in range(steps):
        out = ctrl.step(np.zeros(6), np.zeros(6), DT)
    assert ctrl.prepressurised
    n_pre = arm.prepressurised_segments
    assert np.allclose(out.commands[: 2 * n_pre], p.prepressure)
    assert np.allclose(out.commands[2 * n_pre:12], p.cylinder_min)
    assert np.allclose(out.differential, 0.0)  # common mode only: no bending


def test_gripper_channel_and_hold(arm):
    p = ControllerParams.from_robot(arm)
    ctrl = CurvatureController.from_robot(arm)
    ctrl.reset()
    for _ in range(100):
        out = ctrl.step(np.ones(6), np.zeros(6), DT, gripper_closed=True)
    assert out.commands[12] == pytest.approx(p.gripper_closed)
    frozen = ctrl.hold().commands
    assert np.array_equal(frozen, out.commands)
    assert np.array_equal(ctrl.hold().commands, frozen)  # hold keeps the volumes


@pytest.mark.parametrize("target,meas,dt", [
    (np.zeros(5), np.zeros(6), DT), (np.zeros(6), np.full(6, np.nan), DT), (np.zeros(6), np.zeros(6), 0.0)])
def test_bad_input_is_refused_and_changes_nothing(arm, target, meas, dt):
    ctrl = CurvatureController.from_robot(arm)
    before = ctrl.commands.copy()
    with pytest.raises(ValueError):
        ctrl.step(target, meas, dt)
    assert np.array_equal(ctrl.commands, before)


def test_gains_come_from_the_robot_file(arm, tmp_path):
    text = arm.source.read_text().replace("kp = 90.0", "kp = -1.0")
    path = tmp_path / "soft-arm.toml"
    path.write_text(text)
    with pytest.raises(robots.RobotFileError, match=r"controller\.kp"):
        ControllerParams.from_robot(robots.load(path))
    assert dataclasses.asdict(ControllerParams.from_robot(arm))["kp"] == 90.0
