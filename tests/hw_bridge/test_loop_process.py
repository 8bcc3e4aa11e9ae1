"""The loop process's parent handle (hw_bridge.loop_process.LoopProcess): the newest view's age
on the handle's clock, and restart() after the child was SIGKILLed or went silent: pending
commands fail with the reason, view and failure start over, a new child answers again."""

from __future__ import annotations

import math
import os
import signal
import time
from typing import Any, Iterator

import pytest

from fakes import FakeClock
from hw_bridge.loop_process import LoopProcess, serve_commands

TIMEOUT_S = 30.0  # generous: the machine is shared; no test asserts a wall-clock bound


def _echo_child(commands: Any, replies: Any, tag: str, publish: bool) -> None:
    """A stand-in loop: publishes ``(tag, n)`` views (unless ``publish`` is off: a silent
    child) and answers every command with nothing; ``"hang"`` is never answered."""
    import threading

    stop = threading.Event()

    def views() -> None:
        n = 0
        while publish and not stop.wait(0.02):
            replies.put(("view", (tag, n)))
            n += 1

    threading.Thread(target=views, daemon=True).start()

    def handle(cid: int, cmd: Any) -> None:
        if cmd != "hang":
            replies.put(("reply", cid, None, (tag, cmd)))

    try:
        serve_commands(commands, handle)
    finally:
        stop.set()


class EchoProcess(LoopProcess):
    def __init__(self, tag: str = "echo", publish: bool = True,
                 clock: Any = time.monotonic) -> None:
        super().__init__("echo-loop", clock=clock)
        self.spawn(_echo_child, (self._commands, self._replies, tag, publish))


def wait_for(pred: Any, what: str) -> None:
    end = time.monotonic() + TIMEOUT_S
    while not pred():
        assert time.monotonic() < end, f"timed out waiting for {what}"
        time.sleep(0.01)


@pytest.fixture
def make() -> Iterator[Any]:
    made: list[LoopProcess] = []

    def build(**kw: Any) -> EchoProcess:
        p = EchoProcess(**kw)
        made.append(p)
        return p
    yield build
    for p in made:
        p.close()


def test_view_age_is_measured_on_the_handles_clock(make) -> None:
    clock = FakeClock(50.0)
    p = make(clock=clock)
    wait_for(lambda: p.view is not None, "a view")
    clock.t += 3.25  # no wall time passes: a new view may arrive, stamped with the same time
    first = p.view
    wait_for(lambda: p.view is not first, "a newer view")
    assert p.view_age() == 0.0
    clock.t += 0.7
    assert p.view_age() == pytest.approx(0.7)


def test_view_age_is_infinite_before_the_first_view(make) -> None:
    p = make(publish=False, clock=FakeClock())
    assert p.send("ping").result(TIMEOUT_S) == ("echo", "ping")  # alive, answering, silent
    assert p.view is None and p.view_age() == math.inf


def test_restart_after_sigkill_fails_pending_commands_and_starts_over(make) -> None:
    p = make()
    wait_for(lambda: p.view is not None, "a view")
    hanging = p.send("hang")
    os.kill(p.pid, signal.SIGKILL)
    wait_for(lambda: p.failure is not None, "the death seen")
    assert not p.alive and "SIGKILL" in p.failure
    with pytest.raises(RuntimeError, match="not running"):
        p.send("ping").result(1)

    p.restart()
    with pytest.raises(RuntimeError, match="restarted.*SIGKILL"):
        hanging.result(1)  # failed with the reason, not left hanging
    assert p.failure is None
    assert p.alive and p.send("ping").result(TIMEOUT_S) == ("echo", "ping")
    wait_for(lambda: p.view is not None, "the new child's view")
    assert p.view_age() < math.inf


def test_restart_ends_a_silent_child_that_is_still_alive(make) -> None:
    p = make(publish=False)
    old = p.pid
    hanging = p.send("hang")
    assert p.alive
    p.restart()
    with pytest.raises(ChildProcessError):  # ended and reaped (no zombie left)
        os.waitpid(old, os.WNOHANG)
    with pytest.raises(ProcessLookupError):
        os.kill(old, 0)
    with pytest.raises(RuntimeError, match="restarted"):
        hanging.result(1)
    assert p.alive and p.pid != old
    assert p.send("again").result(TIMEOUT_S) == ("echo", "again")


def test_bridge_health_of_a_dead_or_silent_loop_is_never_armed() -> None:
    """The Hardware panel and the tip target read the link's health from the loop's newest
    view: once the loop is dead, or silent past STALE_VIEW_S, that view's "active, ARMED" is
    not true any more, so health() says why and is not armed."""
    import types

    from hw_bridge.interface import LinkHealth
    from hw_bridge.loop_process import STALE_VIEW_S, ProcessBridgeControls

    link = LinkHealth("active", "/dev/pts/3", None, True, False, False, 0.2, 0.3, 0.2, 10, 10,
                      0, 0, 0, 0, 1.0)
    ctl = types.SimpleNamespace(view=types.SimpleNamespace(link=link), alive=True, failure=None,
                                age=0.1)
    ctl.view_age = lambda: ctl.age
    controls = ProcessBridgeControls(ctl)  # type: ignore[arg-type]
    assert controls.health() == link  # fresh: as published
    ctl.age = STALE_VIEW_S + 0.7
    silent = controls.health()
    assert not silent.armed and silent.state == "unknown: no news from the control loop for 1.2 s"
    ctl.alive, ctl.failure = False, "the control process was killed (SIGKILL)"
    dead = controls.health()
    assert not dead.armed and "not running" in dead.state and "SIGKILL" in dead.state
    assert dead.port == link.port and dead.rtt_ms_p99 == link.rtt_ms_p99  # the rest as last seen
