"""Stand-ins shared by the console tests that drive panels without a browser."""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
from typing import Any, Iterator


class SyncPool:
    """A worker pool that runs the call at once, here (what the spawned worker would return):
    for panels whose IK or planning runs in a process pool."""

    def submit(self, fn: Any, *args: Any, **kwargs: Any) -> cf.Future:
        fut: cf.Future = cf.Future()
        try:
            fut.set_result(fn(*args, **kwargs))
        except Exception as exc:  # noqa: BLE001
            fut.set_exception(exc)
        return fut

    def shutdown(self, wait: bool = True, cancel_futures: bool = False) -> None:
        pass


class FakeClient:
    """What operator_only, app.refuse and app.notify_all use of a viser ClientHandle.

    ``notes`` holds (title, body) of every notification, ``colors`` their colours.
    """

    def __init__(self, cid: int) -> None:
        self.client_id = cid
        self.notes: list[tuple[str, str]] = []
        self.colors: list[str | None] = []
        self.shown: list[FakeNote] = []

    def add_notification(self, title: str, body: str, **kw: object) -> "FakeNote":
        self.notes.append((title, body))
        self.colors.append(kw.get("color"))  # type: ignore[arg-type]
        note = FakeNote(self, title, body, kw.get("auto_close_seconds"))  # type: ignore[arg-type]
        self.shown.append(note)
        return note

    @property
    def shown_now(self) -> list[tuple[str, str]]:
        """(title, body) of the notifications still on screen: not removed, and not closing by
        themselves (those with ``auto_close_seconds`` are gone after it, whatever happens)."""
        return [(n.title, n.body) for n in self.shown if not n.removed and n.auto_close is None]


class FakeNote:
    """A notification handle: ``remove()`` takes it off the screen."""

    def __init__(self, client: FakeClient, title: str, body: str,
                 auto_close: float | None) -> None:
        self.title, self.body, self.auto_close = title, body, auto_close
        self.removed = False

    def remove(self) -> None:
        self.removed = True


class ScopedClient(FakeClient):
    """A ClientHandle stand-in whose widgets and nodes live in the server's own scope (for the
    per-browser replay), recording the files sent to it."""

    def __init__(self, server: Any, cid: int = 99) -> None:
        super().__init__(cid)
        self.gui, self.scene, self.atomic = server.gui, server.scene, server.atomic
        self.downloads: list[tuple[str, bytes]] = []

    def send_file_download(self, name: str, content: bytes) -> None:
        self.downloads.append((name, content))


def user(handle: Any, client: FakeClient, value: Any = None) -> None:
    """What viser does with a browser's click / edit: store the value, then call back."""
    import viser

    if value is not None:
        handle._impl.value = value if isinstance(value, viser.UploadedFile) else type(
            handle._impl.value)(value)
    for cb in list(handle._impl.update_cb):
        cb(viser.GuiEvent(client=client, client_id=client.client_id,  # type: ignore[arg-type]
                          target=handle))


def click_at(panel: Any, client: FakeClient, x: float, y: float) -> None:
    """A click on the table at (x, y), seen from straight above, to ``panel``'s scene click
    callback."""
    import viser

    panel._on_scene_click(viser.SceneClickEvent(client, client.client_id,  # type: ignore[arg-type]
                                                (x, y, 1.0), (0.0, 0.0, -1.0), (0.5, 0.5), None))


class FakeRunner:
    """The extensible arm's runner not started (the in-process mock before the first Execute):
    what the panels read."""

    started = False
    period_s = 0.01
    failure = None
    view = None

    def __init__(self) -> None:
        from hw_bridge.extensible_jobs import RunnerSnapshot

        self.snapshot = RunnerSnapshot("disconnected")

    def stop(self) -> None:
        pass

    def setpoint(self, seq: int, delta: Any) -> None:
        pass

    def view_age(self) -> float:
        return float("inf")

    def restart(self, timeout: float = 5.0) -> None:
        pass


def done_future(result: Any = None) -> Any:
    """A Future that has resolved with ``result`` (what a loop's command returns)."""
    import concurrent.futures as cf

    fut: Any = cf.Future()
    fut.set_result(result)
    return fut


class FakeClock:
    """A clock the test moves by hand (``clock.t += dt``); call it for the time."""

    def __init__(self, t: float = 100.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def console_app(robot: Any, server: Any, *, soft_control: Any = None,
                extensible_runner: Any = None, bridge_controls: Any = None, hardware: Any = None,
                demo: bool = False, mirror_commands: bool = True, tip_sensor: Any = None,
                store: Any = None, **kwargs: Any) -> Any:
    """A ConsoleApp with exactly the services a test names -- the one place tests build them.

    ``soft_control="process"`` starts a real :class:`hw_bridge.soft_arm_process.ControlProcess`
    (simulated arm, default scheduling and CPUs) as ``serve.py`` does; anything else is used as
    given (a fake). ``demo=True`` adds the demo motion (``serve.py --demo``). Nothing else is
    created: a service left out is None, as in production. ``store``: the console's store,
    when a service was built on it first (``hardware_setup.attach``, as serve.py does).
    """
    from console.app import ConsoleApp
    from console.core.demo_motion import DemoMotion
    from console.core.model import model_for
    from console.core.services import ConsoleServices
    from console.core.state import StateStore

    if soft_control == "process":
        from hw_bridge.soft_arm_process import ControlProcess
        soft_control = ControlProcess(robot)
    if store is None:
        store = StateStore(model_for(robot), mirror_commands=mirror_commands)
    services = ConsoleServices(hardware=hardware, soft_control=soft_control,
                               extensible_runner=extensible_runner,
                               bridge_controls=bridge_controls,
                               demo=DemoMotion(store) if demo else None,
                               tip_sensor=tip_sensor)
    return ConsoleApp(robot, server, store=store, services=services, **kwargs)


def open_guard(server: Any) -> Any:
    """A client guard on a bare viser server (no console built on it): every browser counts as
    the operator, values and rates are still checked. ``console.web`` reads no browser's
    messages on a server without a guard (fail closed), and a client only registers with viser
    once its first camera message is read."""
    from console.web.client_guard import ClientGuard

    return ClientGuard(server, is_operator=lambda cid: True, refuse=lambda c, r, a: None)


@contextlib.contextmanager
def upstream_viser(*names: str) -> Iterator[None]:
    """viser without ``console.web``'s patches whose names contain one of ``names`` (all of
    them without names) inside the block -- what upstream viser 1.1.1 does --, every patch
    installed again after it."""
    from console import web
    from console.web.patches import PATCHES

    chosen = [p for p in PATCHES if not names or any(n in p.name for n in names)]
    assert chosen, f"no patch named {names}"
    for p in chosen:
        p.undo()
    try:
        yield
    finally:
        web.install()
        assert web.installed()
