"""The header's truth rule (console.core.arm_status) and its one writer (console.panels.common.loop_header):
a dead or silent loop process is said in the fault tone within 1 s, never ARMED or an active
link from its last view; fresh views are worded by the arm's panels. Fake views, a fake loop
and a fake clock: no processes, no wall-clock timing."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import pytest

from fakes import FakeClock
from console.core.arm_status import STALE_AFTER_S, LoopNews, header_fields, loop_trouble
from console.panels.common.loop_header import REFRESH_S, LoopHeader


@dataclasses.dataclass
class Health:
    state: str = "active"
    armed: bool = True
    fault: str | None = None


@dataclasses.dataclass
class View:
    link: Any = dataclasses.field(default_factory=Health)


class FakeLoop:
    """A loop process handle: views arrive when the test says, aged on a fake clock."""

    def __init__(self, clock: FakeClock) -> None:
        self.clock = clock
        self.view: Any = None
        self.alive = True
        self.failure: str | None = None
        self.pid: int | None = 4242
        self._at: float | None = None

    def publish(self, view: Any) -> None:
        self.view, self._at = view, self.clock()

    def view_age(self) -> float:
        return math.inf if self._at is None else self.clock() - self._at


class FakeHeader:
    def __init__(self) -> None:
        self.fields: dict[str, tuple[str, Any]] = {}

    def show(self, field: str, text: str, tone: Any = None, *, escape: bool = True) -> None:
        self.fields[field] = (text, tone)


ARMED = lambda v: ("approach · waypoint 1 of 5 · ARMED", "busy")  # noqa: E731
ACTIVE = lambda v: ("device emulator · active", "ok")  # noqa: E731


def fields(**news: Any) -> tuple[Any, Any]:
    base = dict(started=True, alive=True, failure=None, age=0.1)
    return header_fields(LoopNews(**{**base, **news}), View(), ARMED, ACTIVE)


def test_a_fresh_view_is_worded_by_the_arm() -> None:
    assert fields(age=0.0) == (ARMED(None), ACTIVE(None))
    assert fields(age=STALE_AFTER_S) == (ARMED(None), ACTIVE(None))  # 0.5 s old: still news


@pytest.mark.parametrize("news, phase", [
    (dict(alive=False, failure="the control process was killed (SIGKILL)"),
     "control loop not running: killed (SIGKILL)"),
    (dict(alive=False), "control loop not running: the process ended"),
    (dict(age=3.24), "no news from the control loop for 3.2 s"),
    (dict(age=STALE_AFTER_S + 0.01), "no news from the control loop for 0.5 s"),
    (dict(alive=True, failure="emulator device: no pty"),
     "control loop failed: emulator device: no pty"),
    (dict(started=False, alive=False, age=math.inf), "control loop not started"),
])
def test_a_dead_or_silent_loop_is_said_in_the_fault_tone_never_armed(news, phase) -> None:
    (text, tone), link = fields(**news)
    assert (text, tone) == (phase, "fault")
    assert link == ("unknown", "fault")
    assert "ARMED" not in text and "active" not in link[0]


def test_a_starting_loop_is_busy_and_claims_nothing() -> None:
    (text, tone), link = fields(age=math.inf)
    assert (text, tone, link) == ("starting the control loop…", "busy", ("unknown", "fault"))
    assert loop_trouble(LoopNews(True, True, None, math.inf)) is not None


def test_the_header_turns_truthful_within_1_s_of_the_last_view_without_new_views() -> None:
    clock = FakeClock()
    loop, header = FakeLoop(clock), FakeHeader()
    lh = LoopHeader(header, loop)
    loop.publish(View())
    lh.show("phase", "approach · waypoint 1 of 5 · ARMED", "busy")
    lh.show("link", "device emulator · active", "ok")
    assert header.fields["phase"][0].endswith("ARMED")
    assert header.fields["link"] == ("device emulator · active", "ok")
    # The process dies right after that view: only the thread's refreshes run from now on,
    # every REFRESH_S; the header must be truthful by 1 s.
    loop.alive, loop.failure = False, "the control process was killed (SIGKILL)"
    lh.refresh()
    assert header.fields["phase"] == ("control loop not running: killed (SIGKILL)", "fault")
    assert header.fields["link"] == ("unknown", "fault")
    assert lh.needs_restart  # the Hardware panel offers Restart control loop

    # Alive but silent: stale once older than 0.5 s, said by the next refresh.
    loop.alive, loop.failure = True, None
    loop.publish(View())
    lh.show("phase", "approach · ARMED", "busy")
    said_at = None
    t0 = clock.t
    while clock.t - t0 <= 1.0:
        clock.t += REFRESH_S
        lh.refresh()
        if "no news" in header.fields["phase"][0]:
            said_at = clock.t - t0
            break
    assert said_at is not None and said_at <= 1.0 and lh.needs_restart
    assert header.fields["phase"][1] == "fault" and header.fields["link"] == ("unknown", "fault")
    # A panel still wording the old view (ARMED) is not believed while stale ...
    lh.show("phase", "approach · ARMED", "busy")
    assert "ARMED" not in header.fields["phase"][0]
    # ... and its old wording is not brought back by the next fresh view: the view's own
    # link health words it until the panel words the new view.
    loop.publish(View(Health(state="inactive", armed=False)))
    lh.refresh()
    assert header.fields["phase"] == ("running · disarmed", "ok")
    assert header.fields["link"] == ("inactive · disarmed", "ok")
    assert not lh.needs_restart and not lh.trouble


def test_without_panels_the_view_link_health_is_worded_and_faults_shown() -> None:
    clock = FakeClock()
    loop, header = FakeLoop(clock), FakeHeader()
    lh = LoopHeader(header, loop)
    lh.refresh()
    assert header.fields["phase"] == ("starting the control loop…", "busy")
    assert lh.trouble and not lh.needs_restart  # only starting: nothing to restart
    loop.publish(View(Health(state="active", armed=True)))
    assert lh.refresh() == (("running · ARMED", "ok"), ("active · ARMED", "ok"))
    loop.publish(View(Health(state="unconfigured", armed=False, fault="link lost")))
    assert lh.refresh()[1] == ("link lost", "fault")
    with pytest.raises(ValueError, match="no field"):
        lh.show("control", "x")
