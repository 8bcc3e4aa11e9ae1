"""A lab's own arm works from one TOML: soft arms of 4 x 80 mm and 8 x 50 mm, extensible arms of
1, 3 and 4 segments (tests/data/robots/), each a copy of a shipped file with only the name,
``segments.count`` and ``segments.length`` changed.

Independent expectations: planar constant-curvature and Delta forward kinematics written out here
(not core.kinematics) check that planned grasps and IK answers really reach; the device's own
HELLO (in-process mock and the emulator process over a pty) reports 2N + 1 or 3N channels;
headless trials through the simulated arm put the object in the bin
(test_custom_robots_trials.py: they run on simulated time, so in the suite's parallel part).

No test here asserts a wall-clock figure: waits have deadlines far above what they take (the
suite's parallel part runs them beside another test on two busy cores), and the links and device
watchdogs are patient (2 s for a STATE, 1 s for the device's watchdog: the most a device
takes), as these tests are about channel counts and motion, not link timing.
"""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from core import robots
from core.control.controller import CurvatureController
from core.control.sim import EmulatorPlant
from core.kinematics.delta_ik import solve_tip_ik
from core.planning.grasp import plan_grasp
from core.planning.paths import build_path, plan_path
from hw_bridge.config import BridgeConfig
from hw_bridge.interface import ReturnType, SerialHardware
from hw_bridge.mock import MockHardware

ROOT = Path(__file__).resolve().parents[2]
DATA = Path(__file__).resolve().parents[1] / "data" / "robots"
SOFT = {"soft-4x80mm": (4, 0.08), "soft-8x50mm": (8, 0.05)}
EXT = {"extensible-1seg": 1, "extensible-3seg": 3, "extensible-4seg": 4}


def load(name: str) -> robots.Robot:
    return robots.load(DATA / f"{name}.toml")


@pytest.mark.parametrize("name", [*SOFT, *EXT])
def test_test_robots_differ_from_the_shipped_file_only_in_name_count_and_length(name):
    shipped = "soft-arm" if name in SOFT else "extensible"
    a = (robots.ROBOTS_DIR / f"{shipped}.toml").read_text().splitlines()
    b = (DATA / f"{name}.toml").read_text().splitlines()
    assert len(a) == len(b)
    changed = {y.split("=")[0].strip() for x, y in zip(a, b) if x != y}
    assert "count" in changed and changed <= {"name", "count", "length"}


# ---- soft planar arms ------------------------------------------------------------------------

def planar_fk(robot: robots.SoftArm, kappa: np.ndarray) -> np.ndarray:
    """Tip pose [x, y, heading]: constant-curvature arcs chained from the base pose."""
    x, y, th = robot.base_pose
    for k in kappa:
        l = robot.segment_length
        if abs(k) < 1e-12:
            x, y = x + l * math.cos(th), y + l * math.sin(th)
        else:
            x += (math.sin(th + k * l) - math.sin(th)) / k
            y -= (math.cos(th + k * l) - math.cos(th)) / k
        th += k * l
    return np.array([x, y, th])


@pytest.mark.parametrize("name", SOFT)
def test_soft_arm_counts_come_from_the_file(name):
    n, length = SOFT[name]
    arm = load(name)
    assert isinstance(arm, robots.SoftArm)
    assert (arm.n_segments, arm.segment_length, arm.drive_cylinders) == (n, length, 2 * n + 1)
    assert arm.planner.weights == (1.0,) * n and arm.trajectory.max_jerk.shape == (n,)
    assert arm.reach == pytest.approx(n * length + math.hypot(0.035, 0.010))
    ctrl = CurvatureController.from_robot(arm)
    assert ctrl.n_channels == 2 * n + 1
    assert BridgeConfig.from_robot(arm).n_motors == 2 * n + 1


def reachable_object(arm: robots.SoftArm) -> tuple[float, float, float]:
    """An object up and to the left, about 0.75 of the arm's length from its base."""
    total = arm.n_segments * arm.segment_length
    return (-0.53 * total, 0.53 * total, arm.capture.nominal_object_radius)


@pytest.mark.parametrize("name", SOFT)
def test_soft_arm_plans_a_grasp_that_really_reaches(name):
    arm = load(name)
    x, y, r = reachable_object(arm)
    plan = plan_grasp(arm, np.zeros(arm.n_segments), (x, y), r)
    assert plan.success, plan.summary()
    assert plan.kappas.shape[1] == arm.n_segments and plan.weights.shape == (arm.n_segments,)
    assert np.all(np.abs(plan.kappas) <= arm.kappa_max + 1e-12)
    # Last waypoint: the palm point w_t = tip + R(heading) w_off sits r + g_off from the centre,
    # the object on the gripper's left (independent FK).
    tip = planar_fk(arm, plan.kappas[-1])
    c, s = math.cos(tip[2]), math.sin(tip[2])
    w = tip[:2] + np.array([c * arm.gripper.w_off_along - s * arm.gripper.g_off,
                            s * arm.gripper.w_off_along + c * arm.gripper.g_off])
    left = np.array([-s, c])
    np.testing.assert_allclose(np.array([x, y]) - w, (r + arm.gripper.g_off) * left, atol=1e-5)


@pytest.mark.parametrize("name", SOFT)
def test_soft_arm_mock_device_has_2n_plus_1_channels(name):
    arm = load(name)
    n = arm.n_segments
    hw = MockHardware(arm)
    hw.config = dataclasses.replace(hw.config, link_timeout_s=2.0, watchdog_s=1.0)
    try:
        assert hw.configure() is ReturnType.OK, hw.fault  # HELLO answered with 2N + 1 motors
        assert hw.device.motors.position.shape == (2 * n + 1,)
        assert hw.activate() is ReturnType.OK, hw.fault
        assert hw.write(np.zeros(13)) is ReturnType.ERROR  # the paper arm's 13: refused
        assert f"{2 * n + 1} finite counts" in hw.fault
        target = np.arange(2 * n + 1) * 10.0
        end = time.monotonic() + 30.0  # (about 0.1 s)
        while time.monotonic() < end and not np.array_equal(hw.positions(), target):
            assert hw.read() is ReturnType.OK and hw.write(target) is ReturnType.OK, hw.fault
            time.sleep(hw.config.period_s)
        np.testing.assert_array_equal(hw.positions(), target)
    finally:
        hw.shutdown()


@pytest.mark.parametrize("name", SOFT)
def test_soft_arm_emulated_plant_bends_the_last_segment_from_its_channels(name):
    arm = load(name)
    n = arm.n_segments
    plant = EmulatorPlant(arm, seed=1, params=arm.sim.replace(stall_rate_hz=0.0))
    demand = np.zeros(2 * n + 1)
    demand[2 * (n - 1)] = 300.0  # last segment, left cylinder
    for _ in range(300):
        plant.step(demand, 0.01)
    pts, _ = plant.mocap_frame()
    assert pts.shape == (n + 1, 3)  # base + N segment ends
    kappa = np.diff(plant.shape()[:, 2]) / arm.segment_length
    want = np.zeros(n)
    want[-1] = 300.0 / arm.sim.counts_per_kappa
    np.testing.assert_allclose(kappa, want, atol=0.02 * want[-1])


class Emulator:
    """``python -m hw_bridge.emulator --robot PATH`` (its first line is the pty path)."""

    def __init__(self, path: Path):
        self.proc = subprocess.Popen([sys.executable, "-m", "hw_bridge.emulator", "--robot",
                                      str(path)], cwd=ROOT, stdout=subprocess.PIPE, text=True)
        assert self.proc.stdout is not None
        self.port = self.proc.stdout.readline().strip()
        assert self.port.startswith("/dev/"), self.port

    def close(self) -> None:
        self.proc.terminate()
        self.proc.wait(timeout=5)


@pytest.mark.parametrize("name,shipped", [("soft-4x80mm", "soft-arm"),
                                          ("extensible-3seg", "extensible")])
def test_emulator_process_answers_with_the_files_channel_count(name, shipped):
    arm = load(name)
    emu = Emulator(DATA / f"{name}.toml")
    try:
        # patient with a just-started emulator on a loaded machine (a run: "no CONFIG_ACK after
        # 4 tries" at the shipped 50 ms per try)
        slow = dataclasses.replace(BridgeConfig.from_robot(arm), link_timeout_s=2.0,
                                   watchdog_s=1.0, hello_timeout_s=10.0, config_retry_s=1.0)
        hw = SerialHardware(slow, emu.port)
        assert hw.configure() is ReturnType.OK, hw.fault
        hw.cleanup()
        # A host expecting the shipped arm's channel count is refused by the handshake.
        other = dataclasses.replace(slow, n_motors=BridgeConfig.from_robot(
            robots.load(shipped)).n_motors)
        hw = SerialHardware(other, emu.port)
        assert hw.configure() is ReturnType.ERROR
        assert f"with {slow.n_motors} motors" in hw.fault
        hw.cleanup()
    finally:
        emu.close()


# ---- extensible arms ---------------------------------------------------------------------------

def delta_tip(arm: robots.ExtensibleArm, delta: np.ndarray) -> np.ndarray:
    """Tip position: each segment an arc of length L0 + dL bent |(dx, dy)| / d toward (dx, dy)."""
    R, p = np.eye(3), np.zeros(3)
    for dx, dy, dl in np.asarray(delta).reshape(-1, 3):
        length, bend = arm.L0 + dl, math.hypot(dx, dy) / arm.d
        if bend < 1e-12:
            local, rot = np.array([0.0, 0.0, length]), np.eye(3)
        else:
            u = np.array([dx, dy, 0.0]) / math.hypot(dx, dy)
            local = length / bend * ((1 - math.cos(bend)) * u + np.array([0, 0, math.sin(bend)]))
            rot = Rotation.from_rotvec(bend * np.cross([0.0, 0.0, 1.0], u)).as_matrix()
        p, R = p + R @ local, R @ rot
    return p


def rack_lengths(arm: robots.ExtensibleArm, delta: np.ndarray) -> np.ndarray:
    """Rack j at angle beta_j = -phi + 2 pi j / 3 has length L - dx cos(beta) - dy sin(beta)."""
    beta = -arm.phi + 2 * np.pi * np.arange(3) / 3
    d = np.asarray(delta).reshape(-1, 3)
    return (arm.L0 + d[:, 2:3]) - d[:, :1] * np.cos(beta) - d[:, 1:2] * np.sin(beta)


def random_posture(arm: robots.ExtensibleArm, rng: np.random.Generator) -> np.ndarray:
    """A posture well inside every rack and bend limit."""
    while True:
        bend = rng.uniform(0, 0.7 * arm.theta_max, arm.n_segments)
        ang = rng.uniform(-np.pi, np.pi, arm.n_segments)
        dl = rng.uniform(0.05, 0.25, arm.n_segments)
        delta = np.column_stack([arm.d * bend * np.cos(ang), arm.d * bend * np.sin(ang), dl])
        L = rack_lengths(arm, delta)
        if L.min() > arm.rack_min + 0.01 and L.max() < arm.rack_max - 0.01:
            return delta


@pytest.mark.parametrize("name", EXT)
def test_extensible_counts_come_from_the_file(name):
    arm = load(name)
    assert isinstance(arm, robots.ExtensibleArm)
    assert (arm.n_segments, arm.n_motors) == (EXT[name], 3 * EXT[name])
    assert BridgeConfig.from_robot(arm).n_motors == 3 * EXT[name]


@pytest.mark.parametrize("name", EXT)
def test_extensible_tip_ik_reaches_a_reachable_target_within_the_rack_limits(name):
    arm = load(name)
    rng = np.random.default_rng(EXT[name])
    for _ in range(4):
        target = delta_tip(arm, random_posture(arm, rng))
        res = solve_tip_ik(arm, target)
        assert res.reachable and res.delta.shape == (arm.n_segments, 3)
        assert np.linalg.norm(delta_tip(arm, res.delta) - target) <= arm.ik.tolerance
        L = rack_lengths(arm, res.delta)
        np.testing.assert_allclose(L, res.lengths, atol=1e-9)
        assert L.min() >= arm.rack_min - 1e-9 and L.max() <= arm.rack_max + 1e-9
        bends = np.hypot(res.delta[:, 0], res.delta[:, 1]) / arm.d
        assert bends.max() <= arm.theta_max + 1e-9


@pytest.mark.parametrize("name", ["extensible-1seg", "extensible-4seg"])
def test_extensible_path_executes_on_the_mock_device(name):
    from hw_bridge.extensible_runner import ExtensibleRunner
    arm = load(name)
    n = arm.n_segments
    start = np.tile([0.0, 0.0, 0.03], (n, 1))
    waypoints = build_path("linear", delta_tip(arm, start), 0.03, "xy")
    mp = plan_path(arm, waypoints, speed=0.1, start_delta=start)
    assert mp.motor_counts.shape[1] == 3 * n
    assert np.all(np.linalg.norm(mp.tips - mp.targets, axis=1) <= arm.ik.tolerance)
    hw = MockHardware(arm)
    hw.config = dataclasses.replace(hw.config, link_timeout_s=2.0, watchdog_s=1.0)
    runner = ExtensibleRunner(arm, lambda: hw).start()
    try:
        assert runner.connecting is not None and runner.connecting.result(30) is None
        runner.bridge_controls.arm()  # connecting never arms: the operator's Arm does
        end = time.monotonic() + 30.0  # (about 0.1 s)
        while runner.snapshot.state != "holding" and time.monotonic() < end:
            time.sleep(0.02)
        assert runner.snapshot.state == "holding", runner.snapshot
        assert hw.device.motors.position.shape == (3 * n,)
        result = runner.wait(runner.execute(mp), timeout=30)
        assert result is not None and result.ok, result
        # Encoders (0 = retracted) -> motor travel m -> racks L = U m -> tip (independent).
        m = hw.positions().reshape(n, 3) / arm.counts_per_metre
        m[-1] += arm.L0
        L = np.flip(np.cumsum(np.flip(m, 0), 0), 0)
        beta = -arm.phi + 2 * np.pi * np.arange(3) / 3
        A = np.column_stack([-np.cos(beta), -np.sin(beta), np.ones(3)])
        delta = np.linalg.solve(A, L.T).T - [0.0, 0.0, arm.L0]
        assert np.linalg.norm(delta_tip(arm, delta) - waypoints[-1]) <= 0.003
    finally:
        runner.close()
        hw.shutdown()


# ---- console -------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["soft-8x50mm", "extensible-3seg"])
def test_console_jogs_every_segment_of_the_file(name, monkeypatch):
    """The console builds for the file's arm with one jog slider per coordinate; a request of the
    file's shape is drawn and the sliders follow it; the paper arm's shape is refused."""
    import viser

    from console.app import ConsoleApp
    from console.core.grasp_session import GraspSession
    from console.panels.common.jog import JogPanel
    # A soft arm's console has its grasp session: no reachability map for this file's arm (a
    # child process of minutes; no cache ships for it), jogging is what is tested here.
    monkeypatch.setattr(GraspSession, "compute_reach", False)
    arm = load(name)
    n = arm.n_segments
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        app = ConsoleApp(arm, server)
        jog = app.panel(JogPanel)
        if isinstance(arm, robots.SoftArm):
            q = np.arange(n, dtype=float) - 3.0
            assert sorted(jog.sliders) == sorted(f"kappa{i}" for i in range(1, n + 1))
        else:
            q = np.tile([0.005, -0.004, 0.05], (n, 1))
            assert len(jog.sliders) == 3 * n
        with pytest.raises(ValueError, match="shape"):
            app.store.request(np.zeros(6 if n != 6 else 5), "jog")  # the paper arm's shape
        with app:
            state = app.store.request(q, "planner")
            end = time.monotonic() + 30.0  # (a few ms)
            while app.last_drawn_seq != state.seq and time.monotonic() < end:
                time.sleep(0.01)
            assert app.last_drawn_seq == state.seq
        np.testing.assert_allclose(np.asarray(app.store.command.q), q)
        if isinstance(arm, robots.SoftArm):
            assert [jog.sliders[f"kappa{i}"].value for i in range(1, n + 1)] == pytest.approx(q)
    finally:
        server.stop()
