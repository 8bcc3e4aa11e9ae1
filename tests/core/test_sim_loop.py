"""Core's thread-free control cycle (core.control.sim_loop) against hw_bridge's loop runner on
its simulated clock: the same seed gives the same trajectory, tick for tick."""

import numpy as np
import pytest

from core import robots
from core.control.grasp_place import immediate
from core.control.sim import SoftArmSim
from core.control.sim_loop import SimLoop
from core.control.stack import ControlStack
from core.planning.grasp import plan_grasp
from hw_bridge.loop import LoopRunner, SimClock
from hw_bridge.loop_devices import SimDevice


@pytest.fixture(scope="module")
def arm():
    return robots.load("soft-arm")


def _setup(arm, seed):
    sim = SoftArmSim(arm, seed=seed)
    sim.place_object(-0.22, 0.20, 0.0165)
    stack = ControlStack(arm, 0.01, immediate(
        lambda req: plan_grasp(arm, req.kappa, req.center, req.radius)))
    return sim, stack


def _row(control, sim):
    """Everything observable after a tick: telemetry and the simulated arm's true state."""
    c = control
    meas = c.kappa_meas if c.kappa_meas is not None else np.full(6, np.nan)
    obj = sim.obj.xy if sim.obj is not None else np.full(2, np.nan)
    return np.concatenate([[c.t, c.armed, c.waypoint, c.replans, c.gripper_closed],
                           c.commands, c.kappa_ref, meas, sim.cylinders, sim.kappa, obj]), c.phase


def _core_run(arm, seed, seconds):
    sim, stack = _setup(arm, seed)
    loop = SimLoop(sim, stack, 0.01)
    rows = []
    loop.run(0.05)
    loop.arm()
    loop.run(0.5)
    loop.start_task()
    for _ in range(round(seconds / 0.01)):
        rows.append(_row(loop.tick(), sim))
    return rows, loop


def _runner_run(arm, seed, seconds):
    sim, stack = _setup(arm, seed)
    runner = LoopRunner(SimDevice(sim), stack, 0.01, clock_ns=SimClock())
    rows = []
    runner.run_sim(0.05)
    runner.arm()
    runner.run_sim(0.5)
    runner.start_task()
    for _ in range(round(seconds / 0.01)):
        runner.run_sim(0.01)
        rows.append(_row(runner.snapshot.control, sim))
    return rows, runner


def test_core_cycle_matches_the_loop_runner_on_a_sim_clock(arm):
    seconds = 12.0
    core_rows, loop = _core_run(arm, 4, seconds)
    hw_rows, runner = _runner_run(arm, 4, seconds)
    assert loop.ticks == runner.ticks == 55 + round(seconds / 0.01)
    phases = [p for _, p in core_rows]
    assert phases == [p for _, p in hw_rows]
    # The run really went somewhere: planned, approached and moved the arm.
    assert {"settling", "approach"} <= set(phases)
    a = np.array([r for r, _ in core_rows])
    b = np.array([r for r, _ in hw_rows])
    assert np.array_equal(a, b, equal_nan=True)
    assert np.ptp(a[:, -8:-2], axis=0).max() > 1.0  # curvatures changed by > 1 1/m
    # Tick k is at k periods of simulated time, as on the runner's SimClock.
    assert np.allclose(a[:, 0], 0.55 + 0.01 * np.arange(len(a)))


def test_a_different_seed_gives_a_different_run(arm):
    a, _ = _core_run(arm, 4, 2.0)
    b, _ = _core_run(arm, 5, 2.0)
    assert not np.array_equal(np.array([r for r, _ in a]), np.array([r for r, _ in b]),
                              equal_nan=True)


def test_commands_run_at_the_next_tick_and_failures_are_reported(arm):
    sim, stack = _setup(arm, 0)
    loop = SimLoop(sim, stack, 0.01)
    seen = []
    loop.submit(lambda s, t: seen.append(t))
    assert seen == []
    loop.run(0.03)
    assert seen == [0.0] and loop.ticks == 3

    def boom(reading, t, periods=1):
        raise RuntimeError("broken fit")
    loop.arm()
    loop.tick()
    assert stack.armed
    stack.update = boom
    c = loop.tick()
    assert loop.update_failures == 1 and "broken fit" in loop.fault
    assert not stack.armed and c is not None and not c.armed  # held and disarmed, as the runner
