"""The console core alone (no viser, no panels) on a fake clock with a fake arm: STOP, a lost,
released or taken-over lease, hold-to-run expiry, a link fault and a dead loop each end motion
through the one route exactly once, with the reason; commands reach the arm only through the
core and never from before a STOP; no motion is queued behind a STOP. The two real supervisors'
rules are checked against stand-ins of the loop processes."""

from __future__ import annotations

import concurrent.futures as cf
from typing import Any

import numpy as np
import pytest

from console.core.access import AccessControl
from console.core.arm_supervisor import (ExtensibleSupervisor, NoArmSupervisor,
                                         SoftArmSupervisor, supervisor_for)
from console.core.console_core import ConsoleCore, MotionStopped
from console.core.model import model_for
from console.core.services import ConsoleServices
from console.core.state import ArmState, StateStore
from core.robots import load
from fakes import FakeClock

SOFT = load("soft-arm")
EXT = load("extensible")


class FakeArm:
    """An arm supervisor that records what the core asked of it."""

    own_source = "loop"

    def __init__(self) -> None:
        self.stops: list[str] = []
        self.forwarded: list[int] = []
        self.takes = True
        self.fault: str | None = None
        self.dead: str | None = None
        self.is_moving = False

    def stop(self, reason: str) -> None:
        self.stops.append(reason)

    def forward(self, state: ArmState) -> bool:
        if self.takes:
            self.forwarded.append(state.seq)
        return self.takes

    @property
    def alive(self) -> bool:
        return self.dead is None

    def failure(self) -> str | None:
        return self.dead

    def link_fault(self) -> str | None:
        return self.fault

    def moving(self) -> bool:
        return self.is_moving

    def view_age(self) -> float:
        return 0.0

    def restart(self) -> None:
        self.dead = None


class Log:
    def __init__(self) -> None:
        self.actions: list[tuple[str, Any]] = []

    def action(self, what: str, client: Any = None, **extra: Any) -> None:
        self.actions.append((what, client))


class Demo:
    def __init__(self) -> None:
        self.stopped: list[str] = []

    def stop(self, reason: str = "") -> None:
        self.stopped.append(reason)


def make(robot: Any = SOFT) -> tuple[ConsoleCore, FakeArm, AccessControl, FakeClock, Log, Demo]:
    clock = FakeClock()
    access = AccessControl(None, lease_s=3.0, warn_s=1.5, clock=clock)
    arm, log, demo = FakeArm(), Log(), Demo()
    store = StateStore(model_for(robot))
    core = ConsoleCore(store, ConsoleServices(demo=demo), access, log,  # type: ignore[arg-type]
                       arm=arm, clock=clock)
    return core, arm, access, clock, log, demo


def test_stop_ends_every_motion_once_records_it_and_keeps_who_and_why() -> None:
    core, arm, access, clock, log, demo = make()
    access.take(1, name="Alice")
    assert core.hold.move_to(1, np.full(SOFT.n_segments, 5.0))
    assert core.hold.tick() is not None and core.hold.active  # a set-point move under way
    core.expect_motion("execute once planned")
    core.stop_motion("STOP pressed by Bob", 2)
    assert arm.stops == ["STOP pressed by Bob"] and demo.stopped == ["STOP pressed by Bob"]
    assert not core.hold.active and core.hold.tick() is None  # jogging ended
    assert core.store.command.source == "stop"
    assert not core.is_expected("execute once planned")
    assert core.stops == 1 and core.stop_generation == 1 and core.holding_after_stop
    last = core.last_stop
    assert last is not None and (last.reason, last.who, last.at) == ("STOP pressed by Bob",
                                                                     "client 2", clock.t)
    assert log.actions[-1] == ("STOP: STOP pressed by Bob", 2)


@pytest.mark.parametrize("how", ["expire", "revoke", "release", "take over"])
def test_losing_the_operator_stops_once_with_the_reason(how: str) -> None:
    core, arm, access, clock, log, _ = make()
    access.take(1, name="Ann")
    assert arm.stops == []  # taking free control moves nothing and stops nothing
    if how == "expire":
        access.heartbeat(1)  # the tab answered once: the lease is lease_s (3 s)
        clock.t += 2.9
        assert access.expire_if_silent() is None and arm.stops == []
        clock.t += 0.2
        access.expire_if_silent()
        want = "Ann's tab went silent for 3 s"
    elif how == "revoke":
        access.revoke("Ann's tab closed", 1)
        want = "Ann's tab closed"
    elif how == "release":
        access.release(1)
        want = "Ann released control"
    else:
        access.take(2, name="Bo")
        want = "Bo took control from Ann"
    assert len(arm.stops) == 1 and arm.stops[0].startswith(want), arm.stops
    assert core.stops == 1 and core.last_stop.reason == arm.stops[0]  # type: ignore[union-attr]
    assert not core.holding_after_stop  # a lost lease is not the operator's STOP


def test_a_held_jog_whose_renewals_stop_ends_in_the_one_route_once() -> None:
    core, arm, access, clock, _, _ = make()
    access.take(1, name="Ann")
    coord = core.hold.model.coordinates[0]
    assert core.hold.hold(1, coord, +1)
    for _ in range(5):
        clock.t += 0.02
        assert core.hold.tick() is not None  # jogging while renewed (renewed at t0)
    clock.t += 0.3  # no renewal for > 300 ms: the tab froze, the network dropped
    assert core.hold.tick() is None
    assert len(arm.stops) == 1 and arm.stops[0].startswith("hold-to-run expired"), arm.stops
    for _ in range(3):
        clock.t += 0.02
        assert core.hold.tick() is None
    assert len(arm.stops) == 1
    # A renewal that comes late (the button is still held) is a new jog, as a fresh press is:
    # the expiry stopped the arm, it did not latch the button (only STOP and a lost lease do).
    assert core.hold.hold(1, coord, +1)
    clock.t += 0.02
    assert core.hold.tick() is not None
    core.hold.release(1)
    assert arm.stops == [arm.stops[0]]


def test_a_released_jog_is_no_stop() -> None:
    core, arm, access, clock, _, _ = make()
    access.take(1, name="Ann")
    coord = core.hold.model.coordinates[0]
    core.hold.hold(1, coord, +1)
    core.hold.tick()
    core.hold.release(1, coord)
    clock.t += 1.0
    assert core.hold.tick() is None and arm.stops == []


def test_a_link_fault_stops_once_per_fault() -> None:
    core, arm, *_ = make()
    core.tick()
    assert arm.stops == []
    arm.fault = "link lost: no valid STATE for 48 ms"
    for _ in range(3):
        core.tick()
    assert arm.stops == ["link lost: link lost: no valid STATE for 48 ms"]
    arm.fault = None  # the operator re-armed
    core.tick()
    arm.fault = "watchdog tripped"  # a new fault is a new event
    core.tick()
    core.tick()
    assert arm.stops[1:] == ["link lost: watchdog tripped"] and core.stops == 2


def test_a_dead_loop_process_stops_once_with_why_it_died() -> None:
    core, arm, *_ = make()
    arm.dead = "the control process was killed (SIGKILL)"
    for _ in range(3):
        core.tick()
    assert arm.stops == ["control loop died: the control process was killed (SIGKILL)"]
    assert core.last_stop is not None and "SIGKILL" in core.last_stop.reason


def test_new_commands_are_forwarded_but_never_stops_the_loops_own_or_older_than_a_stop() -> None:
    core, arm, access, *_ = make()
    store = core.store
    core.tick()
    assert arm.forwarded == []  # the initial command is not new
    jog = store.request(np.full(SOFT.n_segments, 1.0), "jog")
    core.tick()
    core.tick()
    assert arm.forwarded == [jog.seq]  # once
    store.report(np.zeros(SOFT.n_segments), "loop")  # a measurement: not a command
    own = store.request(np.full(SOFT.n_segments, 2.0), "loop")  # the loop's own command
    core.tick()
    assert arm.forwarded == [jog.seq] and own.seq not in arm.forwarded
    late = store.request(np.full(SOFT.n_segments, 3.0), "jog")  # made before the STOP ...
    core.stop_motion("STOP pressed by Ann")
    core.tick()  # ... so neither it nor STOP's own "stay here" command reaches the arm
    assert arm.forwarded == [jog.seq] and late.seq not in arm.forwarded
    after = store.request(np.full(SOFT.n_segments, 4.0), "jog")  # a new jog after the STOP
    core.tick()
    assert arm.forwarded == [jog.seq, after.seq] and not core.holding_after_stop


def test_no_motion_is_queued_behind_a_stop() -> None:
    core, arm, *_ = make()
    started: list[str] = []
    asked = core.stop_generation  # e.g. a Repeatability click, or a target being solved
    assert core.run_if_current(asked, lambda: started.append("first")) is None
    core.stop_motion("STOP pressed by Ann")
    with pytest.raises(MotionStopped):
        core.run_if_current(asked, lambda: started.append("after the STOP"))
    core.expect_motion("execute once planned")
    core.stop_motion("Ann's tab went silent for 3 s")
    assert not core.run_expected("execute once planned", lambda: started.append("planned"))
    core.expect_motion("execute once planned")
    assert core.run_expected("execute once planned", lambda: started.append("planned"))
    assert not core.run_expected("execute once planned", lambda: started.append("twice"))
    assert started == ["first", "planned"]


def test_the_holding_after_stop_state_ends_with_the_next_motion() -> None:
    core, arm, *_ = make()
    core.stop_motion("Ann's tab went silent for 3 s")
    assert not core.holding_after_stop  # the arm was stopped, but not by a STOP
    core.stop_motion("STOP pressed by Ann")
    assert core.holding_after_stop
    arm.is_moving = True  # e.g. the runner follows a new command
    assert not core.holding_after_stop
    arm.is_moving = False
    core.stop_motion("STOP pressed by Ann")
    core.start_motion(lambda: None)
    assert not core.holding_after_stop


def test_a_stop_during_a_motion_holds_though_the_loops_next_views_still_show_it() -> None:
    """A viewer's STOP while the arm moves: the loop's views just after it still show the
    motion (the runner has not yet acted on the STOP). That is not "moving again": the phase
    stays "holding after STOP" once the arm rests, and only motion after that rest ends it."""
    core, arm, *_ = make()
    arm.is_moving = True  # a path runs
    core.stop_motion("STOP pressed by Bob (viewer)")
    assert core.holding_after_stop  # the view from before the STOP took effect
    arm.is_moving = False  # the runner stopped
    assert core.holding_after_stop
    arm.is_moving = True  # moving again after the rest
    assert not core.holding_after_stop


# -- the supervisors' rules, against stand-ins of the loop processes ---------------------------

def done() -> cf.Future:
    fut: cf.Future = cf.Future()
    fut.set_result(None)
    return fut


class Control:
    """The soft arm's ControlProcess as SoftArmSupervisor uses it."""

    def __init__(self) -> None:
        self.view: Any = None
        self.failure: str | None = None
        self.alive = True
        self.sent: list[tuple[str, Any]] = []
        self.pending: cf.Future | None = None  # a stop the loop has not applied yet

    def stop_arm(self, reason: str = "") -> cf.Future:
        self.sent.append(("stop", reason))
        self.pending = cf.Future()
        return self.pending

    def goto(self, q: Any) -> cf.Future:
        self.sent.append(("goto", float(np.asarray(q)[0])))
        return done()

    def view_age(self) -> float:
        return 0.0

    def restart(self, timeout: float = 5.0) -> None:
        self.alive, self.failure = True, None


def soft_view(armed: bool = True, phase: str = "idle", fault: str | None = None) -> Any:
    class C:
        pass

    c = C()
    c.armed, c.phase, c.kappa_meas = armed, phase, np.zeros(SOFT.n_segments)  # type: ignore[attr-defined]

    class V:
        pass

    v = V()
    v.snapshot, v.fault = V(), fault  # type: ignore[attr-defined]
    v.snapshot.control = c  # type: ignore[attr-defined]
    return v


def state(seq: int, value: float = 1.0) -> ArmState:
    return ArmState(np.full(SOFT.n_segments, value), seq, "jog")


def test_the_soft_arm_moves_only_armed_and_idle_and_not_before_it_saw_the_stop() -> None:
    ctl = Control()
    sup = SoftArmSupervisor(ctl)
    assert not sup.forward(state(1))  # no view yet
    ctl.view = soft_view(armed=False)
    assert not sup.forward(state(2))
    ctl.view = soft_view(phase="approach")  # a task runs
    assert not sup.forward(state(3))
    ctl.view = soft_view()
    assert sup.forward(state(4, 4.0)) and ctl.sent == [("goto", 4.0)]
    sup.stop("STOP pressed by Ann")
    assert not sup.forward(state(5))  # the loop has not applied the STOP yet
    ctl.pending.set_result(None)  # type: ignore[union-attr]  # applied (the reply arrived)
    assert not sup.forward(state(6))  # the view that came before the reply is stale
    ctl.view = soft_view(phase="stopped")  # the first view after it: stopped
    assert not sup.forward(state(7))
    ctl.view = soft_view()  # re-armed by the operator: idle
    assert sup.forward(state(8, 8.0))
    assert ctl.sent == [("goto", 4.0), ("stop", "STOP pressed by Ann"), ("goto", 8.0)]
    ctl.view = soft_view(fault="link lost: no valid STATE")
    assert sup.link_fault() == "link lost: no valid STATE" and not sup.failure()
    ctl.alive, ctl.failure = False, "killed"
    assert sup.failure() == "killed"


class Runner:
    """The extensible arm's ExtensibleProcess as ExtensibleSupervisor uses it."""

    def __init__(self) -> None:
        self.started = False
        self.view: Any = None
        self.failure: str | None = None
        self.sent: list[tuple[str, Any]] = []

    def stop(self) -> cf.Future:
        self.sent.append(("hold", None))
        return done()

    def setpoint(self, seq: int, delta: Any) -> None:
        self.sent.append(("setpoint", seq))

    def view_age(self) -> float:
        return 0.0

    def restart(self, timeout: float = 5.0) -> None:
        self.started = True


def test_the_extensible_runner_gets_every_command_once_started_and_holds_on_stop() -> None:
    runner = Runner()
    sup = ExtensibleSupervisor(runner)
    assert not sup.forward(state(1))  # the mock's runner starts on the first Execute
    sup.stop("STOP")
    assert runner.sent == [] and sup.failure() is None  # not started is not dead
    runner.started = True
    assert sup.forward(state(2)) and sup.forward(state(3))
    sup.stop("STOP")
    assert runner.sent == [("setpoint", 2), ("setpoint", 3), ("hold", None)]
    runner.started, runner.failure = False, "the extensible-control process exited (code 1)"
    assert sup.failure() == runner.failure


def test_the_supervisor_is_chosen_by_the_services() -> None:
    assert isinstance(supervisor_for(ConsoleServices()), NoArmSupervisor)
    assert isinstance(supervisor_for(ConsoleServices(soft_control=Control())),  # type: ignore[arg-type]
                      SoftArmSupervisor)
    assert isinstance(supervisor_for(ConsoleServices(extensible_runner=Runner())),  # type: ignore[arg-type]
                      ExtensibleSupervisor)
