"""The soft arm's control process driving the device emulator over a real pty + UDP mocap.

Independent expectations: the curvature fitted from the emulator's mocap markers (the same
frames the loop sees) must reach the commanded goto target; after STOP the demands written to
the device stay frozen; an object placed through grasp_at appears in the emulator's world (its
mocap stream); closing ends the emulator process (checked in /proc, not through our handles).
The Hardware panel's controls (``ControlProcess.bridge_controls``): after Disconnect no DEMAND
leaves the console and the device itself, asked over the released pty by this test, reports
disarmed (not tripped) with still motors; Connect to the same pty brings telemetry back without
arming; only Arm arms; a bad port is a clear fault; the sim and the mock say what they cannot do.

The moves run on a test copy of the soft arm whose trajectory is three times faster
(tests/robot_files.py QUICK_MOTION) and whose link tolerates a starved process (watchdog 1 s,
link timeout 0.8 s; shipped: 50 / 40 ms): these tests are about the process, the link and the
device, not the trajectory's speed or the link's timing, and they run beside other tests on a
busy machine. The test of the default link under CPU hogs keeps the shipped file, as serve.py
starts it (its link losses are a figure: benchmarks/link_gaps.py).
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest

from robot_files import QUICK_MOTION, robot_copy

from hw_bridge.link_supervisor import DISCONNECTED, NO_SERIAL_LINK
from hw_bridge.soft_arm_process import ControlProcess
from core.robots import load
from hw_bridge import protocol as p

SOFT = load("soft-arm")


@pytest.fixture(scope="module")
def quick(tmp_path_factory: pytest.TempPathFactory):
    """The soft arm with QUICK_MOTION and a slack link (watchdog 1 s, link timeout 0.8 s)."""
    folder = tmp_path_factory.mktemp("robots")
    changes = {**QUICK_MOTION, "bridge.watchdog_ms": 1000, "bridge.link_timeout_ms": 800}
    return load(robot_copy("soft-arm", folder, changes, name="soft-arm-quick-slack-link"))


def wait_for(pred, timeout=20.0, what="condition"):
    end = time.monotonic() + timeout
    while True:
        try:
            if pred():
                return
        except (AttributeError, TypeError):
            pass  # view not there yet
        if time.monotonic() > end:
            raise AssertionError(f"{what} not reached within {timeout} s")
        time.sleep(0.02)


def control_when(ctl: ControlProcess, pred, timeout: float = 20.0, what: str = "condition"):
    """The loop's control telemetry once ``pred(control)`` holds for it: checks read that very
    telemetry, not a later view (a mocap frame late by > 50 ms on a busy box leaves one tick
    untracked: no measured curvature, no object)."""
    got = []

    def check() -> bool:
        c = ctl.view.snapshot.control
        if pred(c):
            got.append(c)
            return True
        return False

    wait_for(check, timeout, what)
    return got[-1]


def emulator_children(pid: int) -> list[int]:
    """Pids of ``hw_bridge.emulator`` processes whose parent is ``pid`` (from /proc)."""
    out = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            cmd = (d / "cmdline").read_bytes().split(b"\0")
            ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue
        if ppid == pid and b"hw_bridge.emulator" in cmd:
            out.append(int(d.name))
    return out


def alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def device_state(path: str, timeout: float = 10.0) -> p.State:
    """The device's own STATE, asked by this test over the pty (HELLO only: arms nothing)."""
    from hw_bridge.link import Link
    from hw_bridge.transport import open_serial
    transport = open_serial(path, 1_000_000)
    try:
        link = Link(transport)
        transport.reset_input()
        transport.write(p.DELIMITER)
        link.send(p.Hello())
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            for m in link.poll():
                if isinstance(m, p.State):
                    return m
        raise AssertionError(f"no STATE from the device on {path}")
    finally:
        transport.close()


def test_goto_stop_and_grasp_object_through_the_emulator(quick):
    ctl = ControlProcess(quick, seed=2, device="emulator", sched_priority=None)
    emu_pids: list[int] = []
    try:
        wait_for(lambda: ctl.view.link.state == "inactive", what="configured link")
        emu_pids = emulator_children(ctl._proc.pid)
        assert len(emu_pids) == 1
        assert ctl.view.device == "emulator" and ctl.view.fault is None
        ctl.arm().result(10)
        wait_for(lambda: ctl.view.link.state == "active" and ctl.view.link.armed, what="ARMED")
        wait_for(lambda: ctl.view.snapshot.control.prepressurised, what="pre-pressure")

        target = np.array([4.0, -3.0, 3.0, 2.0, -2.0, 5.0])
        ctl.goto(target).result(10)
        # Measured curvature (fit to the mocap markers) converges to the target.
        c = control_when(ctl, lambda c: np.max(np.abs(c.kappa_meas - target)) < 0.3,
                         timeout=60.0, what="curvature convergence")
        assert c.armed and c.tracking_ok and c.phase in ("idle", "released")
        h = ctl.view.link
        assert h.received > 100 and h.crc_errors == 0 and h.rtt_ms_p50 is not None

        # STOP holds: the demands on the wire stay frozen while the loop keeps running.
        ctl.stop_arm("test STOP").result(10)
        wait_for(lambda: ctl.view.snapshot.control.phase == "stopped", what="stopped")
        held = ctl.view.snapshot.control.commands.copy()
        t0, sent0 = ctl.view.snapshot.t, ctl.view.link.sent
        # (the link's counts and the loop's telemetry are published apart: wait for both)
        wait_for(lambda: ctl.view.snapshot.t > t0 + 0.5 and ctl.view.link.sent > sent0 + 30,
                 what="loop running, demands streamed")
        v = ctl.view
        assert np.array_equal(v.snapshot.control.commands, held)
        assert v.link.armed  # still streaming the held demands
        assert v.snapshot.control.reason == "test STOP" and v.fault is None

        # grasp_at puts the object into the emulator's world: it appears in its mocap stream.
        ctl.grasp_at(-0.16, 0.28, 0.0165).result(10)
        xy = control_when(ctl, lambda c: c.object_xy is not None, what="object tracked").object_xy
        assert np.hypot(xy[0] + 0.16, xy[1] - 0.28) < 0.003
        assert ctl.view.object_xy is not None and ctl.view.object_radius == pytest.approx(0.0165)
        wait_for(lambda: ctl.view.snapshot.control.phase not in ("stopped", "idle"),
                 what="grasp task running")
        ctl.stop_arm("second STOP").result(10)
        wait_for(lambda: ctl.view.snapshot.control.phase == "stopped", what="stopped again")
    finally:
        ctl.close()
    assert not ctl.alive
    # No orphan emulator (one whose parent was terminated ends within 1 s: parent_watch).
    assert emu_pids
    wait_for(lambda: not any(alive(p) for p in emu_pids), what="the emulator ended")


def test_bad_device_is_refused():
    with pytest.raises(ValueError, match="device"):
        ControlProcess(SOFT, device="serial")  # type: ignore[arg-type]


def test_link_fault_stops_commanding_and_does_not_rearm(quick):
    ctl = ControlProcess(quick, seed=3, device="emulator", sched_priority=None)
    try:
        wait_for(lambda: ctl.view.link.state == "inactive", what="configured link")
        (emu,) = emulator_children(ctl._proc.pid)
        ctl.arm().result(10)
        ctl.goto(np.full(6, 3.0)).result(10)
        wait_for(lambda: ctl.view.snapshot.control.kappa_ref[0] > 0.5, what="moving")
        os.kill(emu, signal.SIGKILL)  # the device vanishes mid-motion
        # (the loop's fault and the link's health are published apart: wait for both)
        wait_for(lambda: ctl.view.fault is not None and ctl.view.link.state == "unconfigured",
                 what="fault shown")
        v = ctl.view
        assert v.link.state == "unconfigured" and "link lost" in v.fault
        sent = v.link.sent
        time.sleep(0.5)
        assert ctl.view.link.sent == sent and ctl.view.link.state == "unconfigured"  # no re-arm
        assert ctl.view.stats.read_failures > 0
        with pytest.raises(RuntimeError, match="arm refused"):
            ctl.arm().result(10)  # the operator's Arm tries to reconnect: the port is gone
    finally:
        ctl.close()
    assert not ctl.alive


HOGS = ("while True: pass", "while True: pass",
        # a browser-like load: memory allocated, touched and freed over and over
        "import numpy as np\nwhile True:\n    a = np.ones(8_000_000)\n    a *= 2\n    del a\n")


@pytest.mark.alone  # it loads every core on purpose
@pytest.mark.timing  # tests/conftest.py puts an `alone` test in the alone part only with it
def test_under_cpu_hogs_the_default_link_moves_the_arm_and_a_loss_stops_it_with_its_reason():
    """The default console's pair (loop process + emulator on the real-time CPU, as serve.py
    starts them) moves the arm back and forth for 20 s while two busy loops and a memory
    churner run at normal priority anywhere: the arm reaches its targets (the mocap-fitted
    curvature), and a link loss, when one comes, disarms the arm with its reason, nothing arms
    by itself, and the operator's Arm brings it back. How often the link is lost is a timing
    figure, measured by ``benchmarks/link_gaps.py --hog 2 --churn 1 --hog-nice 0`` (docs/real-time.md,
    "Real time": about 2 a minute on the 2-core VM, each after a ~50 ms stall of the real-time CPU;
    before the CPU partition 1-6 a minute); this test asserted none in 20 s and failed CI."""
    import subprocess
    import sys
    hogs = [subprocess.Popen([sys.executable, "-c", code]) for code in HOGS]
    ctl = ControlProcess(SOFT, seed=5, device="emulator")
    losses: list[str] = []
    reached = 0
    try:
        wait_for(lambda: ctl.view.link.state == "inactive", timeout=60, what="configured link")
        k = 1.0  # 1/m: a swing of 2/m takes about 3 s at the shipped trajectory limits
        end = time.monotonic() + 20.0
        sign = 1.0

        def lost() -> None:  # a loss: disarmed with its reason, and nothing arms by itself
            wait_for(lambda: ctl.view.fault is not None, timeout=5.0, what="the fault shown")
            v = ctl.view
            assert "link lost" in v.fault and not v.snapshot.control.armed, v.fault
            wait_for(lambda: not ctl.view.link.armed, timeout=5.0, what="the link disarmed")
            time.sleep(0.5)
            v = ctl.view
            assert not v.link.armed and not v.snapshot.control.armed, "armed itself"
            losses.append(v.fault)
            armed()  # the operator's act

        def armed() -> None:  # Arm, then wait for the view to say so: it can lag the answer,
            ctl.arm().result(30)  # and a stale view's old fault read as a new loss once
            wait_for(lambda: (v := ctl.view).fault is None and v.link.armed
                     and v.snapshot.control is not None and v.snapshot.control.armed,
                     timeout=30.0, what="the view armed after the operator's Arm")

        armed()
        while time.monotonic() < end:
            target = np.full(SOFT.n_segments, sign * k)
            try:
                ctl.goto(target).result(10)
            except RuntimeError:  # refused: a fault disarmed the arm meanwhile
                lost()
                continue
            try:
                wait_for(lambda: ctl.view.fault is not None or np.max(np.abs(
                    ctl.view.snapshot.control.kappa_meas - target)) < 0.3, timeout=15.0,
                    what="the target reached")
            except AssertionError as exc:
                raise AssertionError(f"{exc}; losses {losses}") from None
            if ctl.view.fault is not None:
                lost()
                continue
            reached += 1
            sign = -sign
        assert reached >= 3, (reached, losses)
        if ctl.view.fault is not None:  # a loss after the last target (a fresh clone's run
            lost()                      # hit one there): handled as any other, then Arm again
        wait_for(lambda: ctl.view.link.armed and ctl.view.link.state == "active", timeout=30.0,
                 what="armed and active again after the operator's Arm")
        v = ctl.view
        assert v.fault is None and v.link.armed and v.link.state == "active", v.fault
        print(f"{reached} targets reached, {len(losses)} link losses in 20 s: {losses}")
    finally:
        for h in hogs:
            h.kill()
            h.wait()
        ctl.close()


def test_mock_device_runs_the_same_plant_in_process(quick):
    ctl = ControlProcess(quick, seed=4, device="mock", sched_priority=None)
    try:
        wait_for(lambda: ctl.view.link.state == "inactive", what="configured mock link")
        assert emulator_children(ctl._proc.pid) == []
        ctl.arm().result(10)
        target = np.array([-3.0, 2.0, 4.0, 0.0, 3.0, -2.0])
        ctl.goto(target).result(10)
        wait_for(lambda: np.max(np.abs(ctl.view.snapshot.control.kappa_meas - target)) < 0.3,
                 timeout=60.0, what="curvature convergence")
        ctl.place_object(0.25, 0.02, 0.02).result(10)
        wait_for(lambda: ctl.view.object_xy is not None, what="object in the mock world")
        assert ctl.view.object_xy == pytest.approx((0.25, 0.02), abs=1e-6)

        # The mock's link can be dropped and re-opened, but it has no other port to go to.
        bc = ctl.bridge_controls
        bc.disconnect()
        wait_for(lambda: bc.health().state == "unconfigured", what="mock disconnected")
        assert not ctl.view.snapshot.control.armed and ctl.view.fault == DISCONNECTED
        with pytest.raises(RuntimeError, match="mock device"):
            ctl.connect_link("/dev/ttyUSB0", 115200).result(10)
        wait_for(lambda: "--port-path" in bc.health().fault, what="refusal shown")
        assert bc.health().state == "unconfigured"
        bc.connect("mock://", 0)
        wait_for(lambda: bc.health().state == "inactive" and ctl.view.fault is None,
                 what="mock reconnected")
        assert not bc.health().armed
    finally:
        ctl.close()


def test_bridge_controls_disconnect_reconnect_and_arm_only_when_asked(quick):
    ctl = ControlProcess(quick, seed=5, device="emulator", sched_priority=50)
    bc = ctl.bridge_controls
    try:
        wait_for(lambda: bc.health().state == "inactive", what="configured link")
        port = bc.health().port
        assert port.startswith("/dev/") and not bc.health().armed
        bc.arm()  # the Hardware panel's Arm: the device is armed and the loop commands it
        wait_for(lambda: bc.health().armed and ctl.view.snapshot.control.armed, what="ARMED")
        ctl.goto(np.full(6, 3.0)).result(10)
        wait_for(lambda: ctl.view.snapshot.control.kappa_ref[0] > 0.5, what="moving")

        bc.disconnect()
        wait_for(lambda: bc.health().state == "unconfigured", what="disconnected")
        wait_for(lambda: ctl.view.fault == DISCONNECTED, what="disconnect shown")
        assert not ctl.view.snapshot.control.armed
        sent = bc.health().sent
        time.sleep(0.3)
        assert bc.health().sent == sent  # no DEMAND leaves the console
        # The device itself (asked over the released pty): disarmed by DISARM, not by its
        # watchdog, and its motors stay where they are.
        first = device_state(port)
        time.sleep(0.3)
        second = device_state(port)
        assert not first.status & p.Status.ARMED and not first.status & p.Status.WATCHDOG_TRIPPED
        assert second.positions == first.positions and not second.status & p.Status.ARMED
        with pytest.raises(RuntimeError, match="disconnected"):
            ctl.arm().result(10)  # no implicit reconnect after the operator's Disconnect
        assert bc.health().state == "unconfigured"

        bc.connect(port, 0)  # the same pty again: telemetry, not armed
        wait_for(lambda: bc.health().state == "inactive", what="reconnected")
        received = bc.health().received
        wait_for(lambda: bc.health().received > received + 30, what="telemetry again")
        v = ctl.view
        assert v.fault is None and not v.link.armed and not v.snapshot.control.armed
        assert v.link.sent == 0  # a new link that has sent no DEMAND
        time.sleep(0.3)
        assert bc.health().sent == 0 and not bc.health().armed  # still: arm only when asked
        bc.arm()
        wait_for(lambda: bc.health().armed and bc.health().sent > 20, what="armed on request")
        assert ctl.view.fault is None and ctl.view.snapshot.control.armed
        bc.disarm()
        wait_for(lambda: bc.health().state == "inactive" and not bc.health().armed,
                 what="disarmed")
        sent = bc.health().sent
        time.sleep(0.3)
        assert bc.health().sent == sent and ctl.view.fault is None

        bc.connect("/dev/no-such-port", 115200)  # bad input: a clear fault, nothing armed
        wait_for(lambda: bc.health().port == "/dev/no-such-port" and bc.health().fault,
                 what="connect fault")
        assert "no-such-port" in bc.health().fault and bc.health().state == "unconfigured"
        assert "no-such-port" in ctl.view.fault
    finally:
        ctl.close()


def test_bridge_controls_on_the_simulated_arm_say_there_is_no_link():
    ctl = ControlProcess(SOFT, seed=6, device="sim", sched_priority=None)
    bc = ctl.bridge_controls
    try:
        wait_for(lambda: ctl.view is not None, what="first view")
        assert bc.health() is None  # no link to show
        with pytest.raises(RuntimeError, match="no serial link"):
            ctl.connect_link("/dev/ttyACM0", 115200).result(10)
        wait_for(lambda: bc.health() is not None, what="health after Connect")
        assert bc.health().fault == NO_SERIAL_LINK and bc.health().state == "unconfigured"
        bc.arm()  # arming the simulated arm still works
        wait_for(lambda: ctl.view.snapshot.control.armed, what="armed")
        bc.disarm()
        wait_for(lambda: not ctl.view.snapshot.control.armed, what="disarmed")
    finally:
        ctl.close()


class _StopLost:
    """The child's command queue, losing the parent's stop request (None): a child too busy or
    too starved to stop within close()'s timeout, as on a loaded machine."""

    def __init__(self, queue) -> None:
        self.queue = queue

    def put(self, item) -> None:
        if item is not None:
            self.queue.put(item)

    def __getattr__(self, name: str):
        return getattr(self.queue, name)


def test_close_returns_once_the_child_has_ended_even_if_it_did_not_stop_in_time():
    """A child that did not stop within the timeout is terminated (then killed), and close()
    returns only once it has ended: closing left it running for a moment (seen as a flaky
    ``assert not ctl.alive`` in test_goto_stop_and_grasp_object_through_the_emulator)."""
    ctl = ControlProcess(SOFT, seed=7, device="sim", sched_priority=None)
    try:
        wait_for(lambda: ctl.view is not None, what="first view")
        ctl._commands = _StopLost(ctl._commands)
        ctl.close(timeout=1.0)
        assert not ctl.alive
    finally:
        ctl.close()
