"""An Execute that waits for its plan is the console core's expected motion: a STOP (or a lost
lease) while the plan is computed cancels it, so the path never starts behind the STOP; without
a STOP it starts when the plan arrives."""

from __future__ import annotations

import concurrent.futures as cf
from typing import Any

import pytest

from core.robots import load
from hw_bridge.extensible_jobs import RunnerSnapshot

EXT = load("extensible")


class DeferredPool:
    """A planner pool whose answers the test releases (:meth:`finish`)."""

    def __init__(self) -> None:
        self.calls: list[tuple[cf.Future, Any, tuple, dict]] = []

    def submit(self, fn: Any, *args: Any, **kwargs: Any) -> cf.Future:
        fut: cf.Future = cf.Future()
        self.calls.append((fut, fn, args, kwargs))
        return fut

    def finish(self) -> None:
        for fut, fn, args, kwargs in self.calls:
            fut.set_result(fn(*args, **kwargs))
        self.calls.clear()

    def shutdown(self, wait: bool = True, cancel_futures: bool = False) -> None:
        pass


class Runner:
    """The extensible runner, started and idle; records the paths it is asked to run."""

    started = True
    period_s = 0.01
    failure = None
    view = None

    def __init__(self) -> None:
        self.snapshot = RunnerSnapshot("holding")
        self.jobs: list[str] = []
        self.holds = 0

    def start(self) -> Runner:
        return self

    def execute(self, path: Any, label: str = "path") -> int:
        self.jobs.append(label)
        return len(self.jobs)

    def wait(self, job: int, timeout: float | None = None) -> None:
        return None

    def stop(self) -> None:
        self.holds += 1

    def setpoint(self, seq: int, delta: Any) -> None:
        pass

    @property
    def bridge_controls(self) -> Any:
        class Controls:
            def health(self) -> None:
                return None
        return Controls()


@pytest.mark.parametrize("stop", [True, False])
def test_a_stop_while_planning_cancels_the_execute_waiting_for_the_plan(server, monkeypatch,
                                                                        stop: bool) -> None:
    from fakes import console_app

    from console.panels.extensible.paths import EXECUTE_ONCE_PLANNED, PathsPanel

    runner = Runner()
    app = console_app(EXT, server, panels=(), extensible_runner=runner)
    try:
        paths = app.add_panel(PathsPanel)
        pool = DeferredPool()
        monkeypatch.setattr(paths, "_plan_pool", lambda: pool)
        paths.size.value = 10.0  # mm: a short path plans quickly
        paths._request_plan(execute=True)  # Execute with no plan yet: it waits for one
        assert app.core.is_expected(EXECUTE_ONCE_PLANNED) and pool.calls
        if stop:
            app.stop_motion("STOP pressed by Bob")
            assert runner.holds == 1  # the runner holds at once
        pool.finish()  # the plan arrives
        assert runner.jobs == ([] if stop else ["path"])
        assert not app.core.is_expected(EXECUTE_ONCE_PLANNED)
        if stop:  # shown as a preview: the plan is there, Execute runs it
            assert 'data-state="previewed"' in paths.status.content
    finally:
        app.stop()
