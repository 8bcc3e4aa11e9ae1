"""The lease on a fake clock: the operator is warned before it lapses, the warning clears when
their tab is heard, a lapse stops the arm, and a page still loading has a grace and gets control
back when it answers (issue #19: a slow browser stopped the arm)."""

from __future__ import annotations

from typing import Any

import pytest
from fakes import FakeClock, console_app

from console.core.access import AccessControl
from console.lease import LeaseMonitor
from console.core.lease_limits import FIRST_ANSWER_S, LEASE_S, WARN_S
from core.robots import load



class FakeHandle:
    """A viser NotificationHandle stand-in: its props as set, and whether it was removed."""

    def __init__(self, title: str, body: str, **props: Any) -> None:
        self.title, self.body, self.removed = title, body, False
        self.auto_close_seconds = props.get("auto_close_seconds")
        self.loading = props.get("loading", False)
        self.color = props.get("color")
        self.with_close_button = props.get("with_close_button", True)

    def remove(self) -> None:
        self.removed = True


class SlowTab:
    """A browser tab on the fake clock: busy (frozen) until ``busy_until`` (None: forever), then
    it answers every probe sent meanwhile within ``answer_s``, in order, as a real tab catches
    up; a probe that would wait past its timeout moves the clock by the timeout and raises, as
    viser's ``get_item`` does."""

    def __init__(self, cid: int, clock: FakeClock) -> None:
        self.client_id = cid
        self.clock = clock
        self.busy_until: float | None = 0.0
        self.answer_s = 0.05
        self.notes: list[FakeHandle] = []
        self.warned_while_probed: list[bool] = []  # was a warning showing at each probe?
        self.local_storage = self

    def freeze(self, seconds: float | None) -> None:
        self.busy_until = None if seconds is None else self.clock.t + seconds

    def get_item(self, key: str, timeout: float | None = None) -> str | None:
        assert key == "console-lease" and timeout is not None and timeout > 0
        self.warned_while_probed.append(any(not n.removed for n in self.notes))
        if self.busy_until is None:
            self.clock.t += timeout
            raise TimeoutError
        answer_at = max(self.clock.t, self.busy_until) + self.answer_s
        if answer_at - self.clock.t > timeout:
            self.clock.t += timeout
            raise TimeoutError
        self.clock.t = answer_at
        return None

    def add_notification(self, title: str, body: str, **props: Any) -> FakeHandle:
        self.notes.append(FakeHandle(title, body, **props))
        return self.notes[-1]


class FakeServer:
    def __init__(self, *tabs: SlowTab) -> None:
        self.clients = {t.client_id: t for t in tabs}

    def get_clients(self) -> dict[int, SlowTab]:
        return dict(self.clients)

    def on_client_disconnect(self, fn: Any) -> None:
        self.disconnect = fn


def rig(**kw: Any) -> tuple[AccessControl, LeaseMonitor, SlowTab, FakeClock, list[str]]:
    clock = FakeClock()
    access = AccessControl(None, clock=clock, **kw)
    tab = SlowTab(1, clock)
    monitor = LeaseMonitor(FakeServer(tab), access)  # type: ignore[arg-type]
    stops: list[str] = []  # every change of holder (the app stops the arm when one goes)
    access.add_listener(lambda new, prev, why: stops.append(why))
    return access, monitor, tab, clock, stops


def settle(monitor: LeaseMonitor, clock: FakeClock, seconds: float, period: float = 0.1) -> None:
    """Run the monitor's loop for ``seconds`` of fake time (its waits between probes)."""
    end = clock.t + seconds
    while clock.t < end:
        monitor.step()
        clock.t += period


def test_the_limits_leave_the_measured_browsers_a_margin() -> None:
    """benchmarks/lease_gaps.py (table in console/core/access.py): worst gap 3.4 s (desktop + 2 busy loops) and
    3.2 s (tablet, 4x throttled); first answer of a throttled tablet 9.7 s. The old limits
    (2 s, 10 s) lapsed on both; the new ones are at least twice the worst measured."""
    assert LEASE_S >= 2 * 3.4 and FIRST_ANSWER_S >= 2 * 9.7
    assert 3.4 < WARN_S < LEASE_S  # past every gap measured
    with pytest.raises(ValueError, match="warn_s"):
        AccessControl(None, lease_s=2.0, warn_s=2.0)


def test_a_silent_tab_is_warned_then_loses_control_and_the_arm_stops() -> None:
    access, monitor, tab, clock, stops = rig(lease_s=3.0, warn_s=1.5)
    access.take(1, name="Ann")
    stops.clear()
    settle(monitor, clock, 1.0)  # answering: no warning
    assert access.status().answered and not tab.notes and not monitor.warning.active
    tab.freeze(None)  # the tab freezes
    t_frozen = access.last_heard(1)
    monitor.step()  # the probe waits only until the warning is due, and shows it
    assert clock.t - t_frozen == pytest.approx(1.5)
    assert access.is_operator(1) and len(tab.notes) == 1 and monitor.warning.active
    note = tab.notes[0]
    assert note.title == "Your browser is slow to answer" and note.color == "yellow"
    assert note.body.startswith("Your browser has been silent for 1.5 s; the arm stops at 3 s")
    assert note.auto_close_seconds is None and note.loading and stops == []
    clock.t += 0.1
    monitor.step()  # the next probe goes out while the warning shows ...
    assert tab.warned_while_probed[-2:] == [False, True] and len(tab.notes) == 1
    assert access.holder is None  # that probe ran out at 3 s: control is gone ...
    assert clock.t - t_frozen == pytest.approx(3.0)  # not a moment later
    assert stops == ["Ann's tab went silent for 3 s"]  # ... and the arm was stopped
    assert note.removed and not monitor.warning.active  # the app's own notice says the rest
    settle(monitor, clock, 1.0)
    assert len(tab.notes) == 1


def test_a_tab_heard_again_clears_its_warning() -> None:
    access, monitor, tab, clock, stops = rig(lease_s=3.0, warn_s=1.5)
    access.take(1)
    stops.clear()
    monitor.step()
    tab.freeze(2.15)  # a long frame: silent past the warning, not up to the lease
    monitor.step()  # shows the warning at 1.5 s ...
    monitor.step()  # ... and the next probe is answered when the frame ends, at 2.2 s
    assert access.is_operator(1) and stops == []
    note = tab.notes[0]
    assert note.title == "Your browser answers again" and "silent for 2.2 s" in note.body
    assert note.auto_close_seconds == monitor.warning.CLOSE_AFTER_S and not note.loading
    assert not monitor.warning.active
    tab.freeze(0)
    settle(monitor, clock, 2.0)
    assert len(tab.notes) == 1 and monitor.warning.shown == 1  # answering: nothing new


def test_a_loading_tab_has_a_grace_is_not_warned_and_gets_control_back_when_it_answers() -> None:
    for desk in (True, False):  # desk: granted on connect; lab: took control with the token
        access, monitor, tab, clock, stops = rig(lease_s=3.0, warn_s=1.5, first_answer_s=20.0,
                                                 first_client_takes_control=desk)
        if desk:
            access.grant_if_free(1)
        else:
            access.take(1)
        stops.clear()
        tab.freeze(19.0)  # the page is still building the console for 19 s
        t0 = clock.t
        settle(monitor, clock, 19.0)
        assert access.is_operator(1) and stops == [] and clock.t - t0 >= 19.0  # in its grace
        assert tab.notes == []  # ... and not warned: nothing is wrong with a loading page
        access.release(1)
        if desk:
            access.grant_if_free(1)
        else:
            access.take(1)
        stops.clear()
        tab.freeze(None)  # this time it takes too long
        settle(monitor, clock, 20.1)
        assert access.holder is None and "did not answer within 20 s" in stops[-1]
        assert tab.warned_while_probed[-1] is False and len(stops) == 1
        assert tab.notes == []
        assert access.lapsed == 1  # not a lost lease: it is waiting for the tab
        tab.freeze(0)  # loaded
        monitor.step()
        assert access.is_operator(1) and access.status().answered and tab.notes == []
        assert stops[-1] == "client 1 has control again (their tab answers again)"


def test_a_lab_tab_that_went_silent_after_answering_must_take_control_again() -> None:
    access, monitor, tab, clock, stops = rig(lease_s=3.0, warn_s=1.5)
    access.take(1)
    monitor.step()
    tab.freeze(None)
    settle(monitor, clock, 3.5)
    assert access.holder is None and access.lapsed is None and "silent for 3 s" in stops[-1]
    tab.freeze(0)
    settle(monitor, clock, 1.0)
    assert access.holder is None  # lab mode: a lost lease is retaken on purpose


def test_a_lapse_stops_the_consoles_arm(server) -> None:
    """The same lapse through a real ConsoleApp: its core stops motion, once, with the reason."""
    clock = FakeClock()
    app = console_app(load("soft-arm"), server, panels=(),
                      access=AccessControl(None, lease_s=3.0, warn_s=1.5, clock=clock))
    tab = SlowTab(1, clock)
    monitor = LeaseMonitor(FakeServer(tab), app.access)  # type: ignore[arg-type]
    app.access.take(1, name="Ann")
    settle(monitor, clock, 1.0)
    assert app.stops == 0
    tab.freeze(None)
    settle(monitor, clock, 3.5)
    assert app.stops == 1 and app.last_stop.reason == "Ann's tab went silent for 3 s"
    assert tab.notes[0].removed  # the warning made way for the app's notice


def test_a_still_console_is_probed_once_a_second_a_jog_ten_times_a_second() -> None:
    """Each probe makes viser's client draw the 3D scene for a quarter of a second; probing a
    still console every 0.1 s kept a software-rendered page drawing without pause. Only a
    running jog needs the 0.1 s heartbeat (it holds 300 ms after the last answer)."""
    jogging = [False]
    monitor = LeaseMonitor(FakeServer(), AccessControl(None),  # type: ignore[arg-type]
                           busy=lambda: jogging[0])
    assert (monitor.probe_period, monitor.idle_period) == (0.1, 1.0)
    assert not monitor.due(0.5) and monitor.due(1.0)
    jogging[0] = True
    assert monitor.due(0.1) and not monitor.due(0.05)
    # The slowest gap a still console adds (one idle period) stays below the warning.
    assert monitor.idle_period + 0.1 < WARN_S
    with pytest.raises(ValueError, match="probe_period"):
        LeaseMonitor(FakeServer(), AccessControl(None), probe_period=2.0)  # type: ignore[arg-type]


def test_the_consoles_lease_probes_fast_only_while_a_jog_runs(server) -> None:
    app = console_app(load("soft-arm"), server, panels=())
    app.access.take(1, name="Ann")
    assert not app.lease.busy()
    assert app.hold.move_to(1, app.store.command.q * 0.5 + 0.5)  # somewhere else (clamped)
    assert app.lease.busy()  # the set-point move steps only on fresh answers
    app.hold.cancel()
    assert not app.lease.busy()


def test_a_still_console_keeps_the_lease_without_probing_its_tab() -> None:
    """Issue 29: each probe makes viser's client redraw the 3D view (a still software-rendered
    page drew 4.7-8.6 frames/s). While nothing moves the tab is not probed and keeps control
    even frozen (it could stop nothing); once motion needs it, the probes resume and a frozen
    tab loses control within the lease, which stops the arm (the listeners)."""
    moving = [False]
    clock = FakeClock()
    access = AccessControl(None, lease_s=3.0, warn_s=1.5, clock=clock)
    tab = SlowTab(1, clock)
    monitor = LeaseMonitor(FakeServer(tab), access,  # type: ignore[arg-type]
                           needed=lambda: moving[0])
    access.take(1, name="Ann")
    stops: list[str] = []  # every change of holder from here (the app stops the arm)
    access.add_listener(lambda new, prev, why: stops.append(why))
    settle(monitor, clock, 1.0)  # a loading tab is probed regardless, until it answers once
    first = len(tab.warned_while_probed)
    assert first >= 1 and access.status().answered
    tab.freeze(None)  # frozen, still: nothing to stop
    settle(monitor, clock, 10.0, period=1.0)
    assert len(tab.warned_while_probed) == first  # not one probe in 10 simulated s
    assert access.holder is not None and not stops and not tab.notes
    moving[0] = True  # the arm moves: the frozen tab must answer, and cannot
    start = clock.t
    settle(monitor, clock, 4.0)
    assert len(tab.warned_while_probed) > first and tab.notes  # probed, warned
    assert access.holder is None and stops == ["Ann's tab went silent for 3 s"]
    assert clock.t - start <= 4.0 + 0.2


def test_the_consoles_lease_is_needed_only_while_motion_runs(server) -> None:
    app = console_app(load("soft-arm"), server, panels=())
    app.access.take(1, name="Ann")
    assert not app.lease.needed()  # a still console
    assert app.hold.move_to(1, app.store.command.q * 0.5 + 0.5)
    assert app.lease.needed()  # a jog held
    app.hold.cancel()
    assert not app.lease.needed()
