"""One arm's 100 Hz loop in its own process: the wrapper both arms' control processes share.

In the console process the render thread, viser's event loop and the panels hold the GIL for
milliseconds at a time, and on a loaded machine a thread holding it is descheduled while the
real-time loop waits for it: a loop *thread* there misses deadlines and loses its serial link
(see the README's "Real time" section). So each arm's loop runs in a spawned child whose every
thread is real-time (:mod:`hw_bridge.realtime`) and pinned to the real-time CPU
(:mod:`hw_bridge.cpu_partition`).

Parent side, :class:`LoopProcess`: typed commands (:mod:`hw_bridge.commands`) go down a queue
with an id, and :meth:`LoopProcess.send` returns a Future that the child's reply resolves (with
the loop's error, if it refused); the child publishes a view (``("view", v)``), newest in
:attr:`LoopProcess.view` (a reference swap, no lock for readers); other messages go to
:meth:`LoopProcess.on_message`. Child side, :func:`serve_commands` reads the queue until the
parent says stop or goes away, and :func:`reply_when_done` answers a command once the loop ran it.
"""

from __future__ import annotations

import atexit
import concurrent.futures as cf
import itertools
import multiprocessing
import queue
import threading
from typing import Any, Callable

from hw_bridge.commands import Arm, Connect, Disarm, Disconnect
from hw_bridge.parent_watch import exit_reason, run_reporting


class LoopProcess:
    """Parent-side handle of a loop process; a subclass starts it with :meth:`spawn`.

    Args:
        name: The child process's name (``ps``, ``top``).
    """

    def __init__(self, name: str) -> None:
        self.name = name
        self.failure: str | None = None
        self.view: Any = None
        ctx = multiprocessing.get_context("spawn")
        self._ctx = ctx
        self._commands = ctx.Queue()
        self._replies = ctx.Queue()
        self._proc: Any = None
        self._ids = itertools.count(1)
        self._pending: dict[int, cf.Future] = {}
        self._lock = threading.Lock()

    def spawn(self, target: Callable[..., None], args: tuple[Any, ...]) -> None:
        """Start ``target(*args)`` in the child (``args`` include this handle's
        ``_commands`` / ``_replies`` queues where the child expects them) and the reader."""
        # Not a daemon: the child starts processes of its own. close() (also at exit) ends it.
        self._proc = self._ctx.Process(target=run_reporting, name=self.name,  # (a failure's
                                       args=(target, self._replies, *args))  # reason -> failure)
        self._proc.start()
        threading.Thread(target=self._read, name=f"{self.name}-replies", daemon=True).start()
        atexit.register(self.close)

    def _read(self) -> None:
        while True:
            try:
                msg = self._replies.get(timeout=1.0)
            except queue.Empty:
                if not self._proc.is_alive():  # killed or crashed: the panel says so
                    self.failure = self.failure or exit_reason(self._proc.exitcode)
                    return
                continue
            except (EOFError, OSError):
                return
            if msg[0] == "view":
                self.view = msg[1]
            elif msg[0] == "failed":
                self.failure = msg[1]
            elif msg[0] == "reply":
                with self._lock:
                    fut = self._pending.pop(msg[1], None)
                if fut is not None:
                    if msg[2] is None:
                        fut.set_result(msg[3] if len(msg) > 3 else None)
                    else:
                        fut.set_exception(RuntimeError(msg[2]))
            else:
                self.on_message(msg)

    def on_message(self, msg: tuple[Any, ...]) -> None:
        """A message other than view / failed / reply (reader thread)."""

    def send(self, cmd: Any) -> cf.Future:
        """Queue a command for the loop; the Future resolves when the loop applied it."""
        fut: cf.Future = cf.Future()
        if not self.alive:
            fut.set_exception(RuntimeError(f"the {self.name} process is not running"))
            return fut
        cid = next(self._ids)
        with self._lock:
            self._pending[cid] = fut
        self._commands.put((cid, cmd))
        return fut

    @property
    def alive(self) -> bool:
        return self._proc is not None and self._proc.is_alive()

    def close(self, timeout: float = 5.0) -> None:
        """Stop the loop and the child process."""
        if self._proc is None:
            return
        if self._proc.is_alive():
            self._commands.put(None)
            self._proc.join(timeout)
        if self._proc.is_alive():
            self._proc.terminate()


class ProcessBridgeControls:
    """:class:`hw_bridge.controls.BridgeControls` over a :class:`LoopProcess`.

    Every method only queues a bridge command (:mod:`hw_bridge.commands`) for the child's loop
    thread (the only writer to the hardware, through its
    :class:`~hw_bridge.link_supervisor.LinkSupervisor`) and returns at once; refusals land in
    ``health().fault``. ``health()`` is the ``link`` of the newest published view. On the soft
    arm Arm / Disarm are the Control panel's too: the link is activated (ARM) *and* the control
    stack starts commanding (holding where the arm is), since an armed device without demands
    trips its watchdog within ``watchdog_ms``; on its simulated arm Connect / Disconnect do
    nothing and health() says so.
    """

    def __init__(self, ctl: LoopProcess):
        self.ctl = ctl

    def connect(self, port: str, baud: int) -> None:
        self.ctl.send(Connect(str(port).strip(), int(baud)))

    def disconnect(self) -> None:
        self.ctl.send(Disconnect())

    def arm(self) -> None:
        self.ctl.send(Arm())

    def disarm(self) -> None:
        self.ctl.send(Disarm())

    def health(self) -> Any:
        """The newest published :class:`~hw_bridge.interface.LinkHealth` (None: no link yet)."""
        view = self.ctl.view
        return None if view is None else view.link


def serve_commands(commands: Any, handle: Callable[[int, Any], None]) -> None:
    """Child: ``handle(cid, cmd)`` for every command until ``None`` or the parent is gone."""
    parent = multiprocessing.parent_process()
    while True:
        try:
            msg = commands.get(timeout=1.0)
        except queue.Empty:
            if parent is not None and not parent.is_alive():
                return  # the console went away: stop the arm's loop too
            continue
        if msg is None:
            return
        handle(*msg)


def reply_when_done(replies: Any, cid: int, fut: cf.Future, with_result: bool = False) -> None:
    """Child: answer command ``cid`` once the loop ran it: its error text, or None (and, with
    ``with_result``, the loop's picklable result for the parent's Future)."""
    def done(f: cf.Future) -> None:
        exc = f.exception()
        if exc is not None:
            replies.put(("reply", cid, str(exc)))
        else:
            replies.put(("reply", cid, None, f.result()) if with_result else ("reply", cid, None))
    fut.add_done_callback(done)
