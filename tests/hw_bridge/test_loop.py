"""Loop runner: sim-clock determinism, overrun counting and skipping (injected clock), command
queue from another thread, planning in another process, the hardware adapter.

The schedule is checked on :class:`SimClock` only; the one real-time thread test waits (20 s
deadlines) without timing anything. Real-time figures (period error, overruns) are
benchmarks/bench_control_loop.py's."""

import threading
import time

import numpy as np
import pytest

from core import robots
from core.control.grasp_place import PlanRequest, immediate
from core.control.sim import SoftArmSim
from core.control.stack import ControlStack
from hw_bridge.loop import LoopRunner, SimClock
from hw_bridge.loop_devices import HardwareDevice, SimDevice
from hw_bridge.planner_process import ProcessPlanner

MS = 1_000_000


@pytest.fixture(scope="module")
def arm():
    return robots.load("soft-arm")


def no_plan(req):
    raise AssertionError("no planning expected")


def sim_runner(arm, seed=0, obj=None):
    sim = SoftArmSim(arm, seed=seed)
    if obj is not None:
        sim.place_object(*obj)
    stack = ControlStack(arm, 0.01, immediate(no_plan))
    return LoopRunner(SimDevice(sim), stack, 0.01, clock_ns=SimClock()), sim, stack


def record(runner, seconds):
    out = []
    for _ in range(round(seconds / 0.01)):
        runner.run_sim(0.01)
        c = runner.snapshot.control
        out.append(np.concatenate([[c.t], c.commands, c.kappa_ref,
                                   c.kappa_meas if c.kappa_meas is not None else np.full(6, np.nan)]))
    return np.array(out)


def test_sim_clock_is_deterministic(arm):
    runs = []
    for seed in (5, 5, 6):
        runner, sim, stack = sim_runner(arm, seed, (-0.2, 0.2, 0.0165))
        runner.run_sim(0.05)
        runner.arm()
        runner.goto(np.array([2.0, 3.0, 4.0, 4.0, 3.0, 2.0]))
        runs.append(record(runner, 3.0))
        assert runner.overruns == 0 and runner.ticks == 305
    a, b, c = runs
    assert np.array_equal(a, b, equal_nan=True)
    assert not np.array_equal(a, c, equal_nan=True)
    assert np.allclose(a[:, 0], 0.05 + 0.01 * np.arange(len(a)))  # exactly one period per tick


class StubStack:
    """Records (t, periods) of every update; never writes."""

    armed = False

    def __init__(self):
        self.calls = []

    def update(self, reading, t, periods=1):
        self.calls.append((round(t, 9), periods))
        return None, None

    def stop(self, t, reason):
        pass

    def device_fault(self, t, reason):
        return None


class WorkDevice:
    """Device whose read 'takes' work_ns[tick] on the injected clock."""

    def __init__(self, clock, work_ms, runner_box):
        self.clock, self.work = clock, work_ms
        self.box = runner_box
        self.n = 0

    def read(self, t):
        self.clock.now_ns += round(self.work.get(self.n, 1.0) * MS)
        self.n += 1
        if self.n >= 12:
            self.box[0]._stop.set()
        return object()

    def write(self, commands, t):
        return True

    def cylinders(self):
        return None


def test_real_time_loop_counts_and_skips_overruns_without_catching_up():
    clock = SimClock(1_000 * MS)
    box = []
    dev = WorkDevice(clock, {5: 25.0, 9: 10.0}, box)
    stack = StubStack()
    runner = LoopRunner(dev, stack, 0.01, clock_ns=clock, sleep_until=clock.sleep_until,
                        timer_ns=clock)
    box.append(runner)
    runner._run()  # the real-time loop body, on the injected clock, in this thread
    ts = [t for t, _ in stack.calls]
    periods = [p for _, p in stack.calls]
    # Tick 5 starts at 50 ms and ends at 75 ms: deadlines 60 and 70 ms are missed (2 overruns),
    # skipped (no back-to-back catch-up ticks), and the next tick runs at 80 ms, told that
    # three periods passed. Tick 9 (at 110 ms) takes exactly one period: not an overrun.
    assert ts == pytest.approx([0.0, 0.01, 0.02, 0.03, 0.04, 0.05, 0.08, 0.09, 0.10, 0.11,
                                0.12, 0.13])
    assert periods == [1, 1, 1, 1, 1, 1, 3, 1, 1, 1, 1, 1]
    assert runner.overruns == 2
    st = runner.stats()
    assert st.ticks == 12 and st.overruns == 2
    assert st.work_ms_p99 == pytest.approx(25.0, rel=0.2)
    assert st.period_error_ms_max == pytest.approx(0.0, abs=1e-9)  # skipped periods accounted
    # The long ticks (the 6th and the 10th) are kept with where their time went.
    slow = [(s.tick, round(s.read_ms, 6), s.missed, s.late_ms) for s in runner.slow_ticks]
    assert slow == [(6, 25.0, 2, 0.0), (10, 10.0, 0, 0.0)]


def test_a_late_wake_up_is_kept_as_a_slow_tick():
    clock = SimClock(0)
    box = []
    dev = WorkDevice(clock, {}, box)
    late = {4: 3 * MS}  # the 4th wake-up comes 3 ms after its deadline (a GIL or the kernel)
    calls = []

    def sleep_until(deadline_ns):
        calls.append(deadline_ns)
        clock.sleep_until(deadline_ns + late.get(len(calls), 0))

    dev.work = {i: 0.2 for i in range(12)}
    runner = LoopRunner(dev, StubStack(), 0.01, clock_ns=clock, sleep_until=sleep_until,
                        timer_ns=clock)
    box.append(runner)
    runner._run()
    assert [(s.tick, s.late_ms, s.missed) for s in runner.slow_ticks] == [(5, 3.0, 0)]
    assert runner.overruns == 0


class TimedReads:
    """A device whose reads take ``work_ms[n]`` on the injected clock (n: the read's index)."""

    def __init__(self, clock, work_ms):
        self.clock, self.work, self.n = clock, work_ms, 0

    def read(self, t):
        self.clock.now_ns += round(self.work[self.n] * MS)
        self.n += 1
        return object()

    def write(self, commands, t):
        return True

    def cylinders(self):
        return None


def test_stats_are_the_percentiles_of_the_kept_ticks(monkeypatch):
    import hw_bridge.loop as loop_module
    monkeypatch.setattr(loop_module, "_STATS_WINDOW", 64)  # 150 ticks wrap the window twice
    work = np.random.default_rng(3).uniform(0.1, 4.0, 150)  # (the clock counts whole ns)
    clock = SimClock()
    runner = LoopRunner(TimedReads(clock, work), StubStack(), 0.01, clock_ns=clock,
                        sleep_until=clock.sleep_until, timer_ns=clock)
    assert runner.run_sim(1.5) == 150
    for last, kept in ((40, work[-40:]), (10, work[-10:]), (None, work[-64:])):
        st = runner.stats(last=last)
        assert st.work_ms_p50 == pytest.approx(np.percentile(kept, 50), abs=1e-5)
        assert st.work_ms_p99 == pytest.approx(np.percentile(kept, 99), abs=1e-5)
        assert st.read_ms_p99 == pytest.approx(np.percentile(kept, 99), abs=1e-5)
        assert st.update_ms_p99 == st.write_ms_p99 == 0.0
        assert st.period_error_ms_p99 == pytest.approx(0.0, abs=1e-9)  # every tick on time


def test_what_the_console_is_sent_holds_plain_numbers():
    """The snapshot and the slow ticks are pickled for the console 30 times a second: plain
    Python numbers (a numpy scalar pickles some 50 times slower, holding the loop's GIL)."""
    import dataclasses
    import pickle
    clock = SimClock()
    runner = LoopRunner(TimedReads(clock, [1.5] * 20), StubStack(), 0.01, clock_ns=clock,
                        sleep_until=clock.sleep_until, timer_ns=clock)
    runner.run_sim(0.2)
    assert len(runner.slow_ticks) == 20  # every read took 1.5 ms: all kept
    values = [v for s in runner.slow_ticks for v in dataclasses.astuple(s)]
    values += [getattr(runner.snapshot, f.name) for f in dataclasses.fields(runner.snapshot)
               if f.name not in ("control", "fault")]
    assert {type(v) for v in values} <= {int, float}
    assert runner.slow_ticks[-1].read_ms == pytest.approx(1.5)
    assert len(pickle.dumps(tuple(runner.slow_ticks))) < 20 * 100


def test_commands_from_another_thread_are_applied_by_the_loop(arm):
    runner, sim, stack = sim_runner(arm)
    runner.run_sim(0.05)
    results = {}

    def gui():
        results["arm"] = runner.arm()
        results["goto"] = runner.goto(np.full(6, 3.0))
        results["bad"] = runner.goto(np.full(6, 99.0))

    th = threading.Thread(target=gui)
    th.start()
    th.join()
    assert not results["arm"].done()  # queued: nothing happens off the loop thread
    runner.run_sim(0.01)
    assert results["arm"].result() is None and results["goto"].result() is None
    with pytest.raises(ValueError, match="beyond"):
        results["bad"].result()
    assert np.allclose(stack.traj.target, 3.0)  # the bad command changed nothing
    runner.run_sim(8.0)
    assert np.allclose(runner.snapshot.control.kappa_meas, 3.0, atol=0.5)


def test_real_time_thread_runs_and_stops(arm):
    runner, sim, stack = sim_runner(arm)
    with pytest.raises(RuntimeError, match="SimClock"):
        runner.start()
    runner = LoopRunner(SimDevice(sim), stack, 0.01)  # real clock
    runner.start()
    try:
        runner.arm().result(timeout=20)
        runner.goto(np.full(6, 2.0)).result(timeout=20)
        deadline = time.monotonic() + 20
        while runner.ticks < 30 and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        runner.stop(timeout=20)
    assert not runner.running and runner.ticks >= 30
    n = runner.ticks
    time.sleep(0.05)
    assert runner.ticks == n  # really stopped
    assert runner.snapshot.control.armed


def test_stop_holds_the_arm(arm):
    runner, sim, stack = sim_runner(arm)
    runner.run_sim(0.05)
    runner.arm()
    runner.goto(np.full(6, 8.0))
    runner.run_sim(1.0)  # mid-motion
    runner.stop_arm()
    runner.run_sim(0.02)
    held = runner.snapshot.control.commands.copy()
    assert runner.snapshot.control.phase == "stopped"
    runner.run_sim(2.0)
    assert np.array_equal(runner.snapshot.control.commands, held)  # volumes frozen
    k = sim.kappa.copy()
    runner.run_sim(1.0)
    assert np.allclose(sim.kappa, k, atol=1e-3)  # the arm holds its shape


def test_planning_runs_in_another_process(arm):
    planner = ProcessPlanner(arm.source)
    try:
        fut = planner(PlanRequest(np.zeros(6), np.array([-0.22, 0.2]), 0.0165))
        plan = fut.result(timeout=60)
    finally:
        planner.close()
    assert plan.kappas.shape[1] == 6 and len(plan.kappas) >= 1
    assert np.allclose(plan.center, [-0.22, 0.2])


def test_a_dead_planning_process_fails_one_plan_with_a_reason_and_is_replaced(arm):
    import os
    import signal
    planner = ProcessPlanner(arm.source)
    try:
        planner.warm.result(timeout=60)
        (pid,) = [p.pid for p in planner.pool._processes.values()]
        os.kill(pid, signal.SIGKILL)  # as if it crashed
        req = PlanRequest(np.zeros(6), np.array([-0.22, 0.2]), 0.0165)
        deadline = time.monotonic() + 30
        fut = planner(req)  # the pool may not have noticed yet: then this plan fails on its own
        while planner.restarts == 0 and time.monotonic() < deadline:
            with pytest.raises(Exception):
                fut.result(timeout=30)
            fut = planner(req)
        assert planner.restarts == 1
        with pytest.raises(RuntimeError, match="planning process had ended"):
            fut.result(timeout=20)
        plan = planner(req).result(timeout=60)  # the new worker plans
        assert np.allclose(plan.center, [-0.22, 0.2])
    finally:
        planner.close()


def test_an_exception_in_the_update_stops_and_disarms_but_the_loop_goes_on(arm):
    runner, sim, stack = sim_runner(arm)
    runner.arm()
    runner.run_sim(0.1)
    assert stack.armed
    real_step = stack.machine.step

    def broken(obs):
        raise ZeroDivisionError("boom")

    stack.machine.step = broken
    ticks = runner.snapshot.tick
    runner.run_sim(0.05)
    assert runner.snapshot.tick == ticks + 5  # every tick ran
    assert runner.update_failures == 1  # disarmed after the first: not stepped again
    assert "control update failed: ZeroDivisionError: boom" in runner.fault
    c = runner.snapshot.control
    assert c.phase == "stopped" and "boom" in c.reason and not c.armed and not stack.armed
    stack.machine.step = real_step
    runner.arm()  # the operator arms again: it works
    runner.run_sim(0.05)
    assert runner.snapshot.control.armed


class StraightMocap:
    """A motion-capture source that always sees the straight arm (fresh frames)."""

    def __init__(self, arm):
        from core.kinematics.planar import forward_kinematics
        self.points = forward_kinematics(np.zeros(6), arm.lengths, arm.base_pose)

    def latest(self):
        from hw_bridge.mocap import MocapFrame
        return MocapFrame(1, 0.0, time.monotonic(), self.points.copy(), True)


class FakeHardware:
    """HardwareInterface stand-in: records writes, fails reads on demand (no timing)."""

    def __init__(self):
        from hw_bridge.interface import ReturnType
        self.ok, self.err = ReturnType.OK, ReturnType.ERROR
        self.fail_read = False
        self.fault = None
        self.written = []

    def read(self):
        if self.fail_read:
            self.fault = "link lost: no valid STATE for 45 ms"
            return self.err
        return self.ok

    def write(self, counts):
        self.written.append(np.array(counts))
        return self.ok

    def positions(self):
        return np.zeros(13, dtype=np.int64)


def test_hardware_device_adapter_prepressurises_and_stops_on_link_loss(arm):
    hw = FakeHardware()
    dev = HardwareDevice(hw, StraightMocap(arm), arm.n_segments, object_radius=0.0165)
    stack = ControlStack(arm, 0.01, immediate(no_plan))
    runner = LoopRunner(dev, stack, 0.01, clock_ns=SimClock())
    runner.run_sim(0.01)
    runner.arm()
    runner.run_sim(0.2)
    c = runner.snapshot.control
    assert c.tracking_ok and c.armed and np.allclose(c.kappa_meas, 0.0, atol=1e-9)
    assert hw.written and np.allclose(hw.written[-1][:4], 150.0) and np.allclose(hw.written[-1][4:12], 0, atol=1e-9)
    hw.fail_read = True
    runner.run_sim(0.01)
    assert runner.read_failures == 1 and stack.machine.phase.value == "stopped"
    assert "link lost" in stack.machine.reason
    c = runner.snapshot.control  # what the Control panel shows: stopped, why, not commanded
    assert c.phase == "stopped" and "link lost" in c.reason and not c.armed and not stack.armed
    n = len(hw.written)
    hw.fail_read = False
    runner.run_sim(0.05)
    assert np.array_equal(hw.written[-1], hw.written[n - 1])  # frozen after the fault


def test_hardware_device_reads_mock_hardware(arm):
    from mock_lockstep import Lockstep
    rig = Lockstep(arm)  # the link's clock stops after the handshake: no 40 ms race
    hw = rig.hw
    try:
        rig.connect_and_arm()
        dev = HardwareDevice(hw, StraightMocap(arm), arm.n_segments, object_radius=0.0165)
        reading = dev.read(0.0)  # right after activate: telemetry is fresh
        assert reading is not None, dev.fault
        assert np.allclose(reading.markers, StraightMocap(arm).points[1:, :2])
        assert dev.write(np.zeros(13), 0.0) and dev.cylinders().shape == (13,)
    finally:
        hw.shutdown()
