"""One arm's 100 Hz loop in its own process: the wrapper both arms' control processes share.

In the console process the render thread, viser's event loop and the panels hold the GIL for
milliseconds at a time, and on a loaded machine a thread holding it is descheduled while the
real-time loop waits for it: a loop *thread* there misses deadlines and loses its serial link
(see docs/real-time.md). So each arm's loop runs in a spawned child whose every
thread is real-time (:mod:`hw_bridge.realtime`) and pinned to the real-time CPU
(:mod:`hw_bridge.cpu_partition`).

Parent side, :class:`LoopProcess`: typed commands (:mod:`hw_bridge.commands`) go down a queue
with an id, and :meth:`LoopProcess.send` returns a Future that the child's reply resolves (with
the loop's error, if it refused); the child publishes a view (``("view", v)``), newest in
:attr:`LoopProcess.view` (a reference swap, no lock for readers) and its age in
:meth:`LoopProcess.view_age`, and every loop tick in batches (``("ticks", b)``) to
:attr:`LoopProcess.tick_listeners`; other messages go to :meth:`LoopProcess.on_message`. A dead or
silent child is replaced by :meth:`LoopProcess.restart` (a new one, disarmed, same arguments). Child side, :func:`serve_commands` reads the queue until the
parent says stop or goes away, and :func:`reply_when_done` answers a command once the loop ran it.
"""

from __future__ import annotations

import atexit
import dataclasses
import concurrent.futures as cf
import itertools
import math
import multiprocessing
import queue
import threading
import time
from typing import Any, Callable

from hw_bridge.commands import Arm, Connect, Disarm, Disconnect
from hw_bridge.parent_watch import exit_reason, run_reporting


STALE_VIEW_S = 0.5  # a published view older than this is not the loop's state any more


class LoopProcess:
    """Parent-side handle of a loop process; a subclass starts it with :meth:`spawn`.

    Args:
        name: The child process's name (``ps``, ``top``).
        clock: Seconds on a monotonic clock: when a view arrived (:meth:`view_age`); tests
            pass a fake one.
    """

    def __init__(self, name: str, clock: Callable[[], float] = time.monotonic) -> None:
        self.name = name
        self.clock = clock
        self._failure: str | None = None
        self.view: Any = None
        self._view_at: float | None = None
        ctx = multiprocessing.get_context("spawn")
        self._ctx = ctx
        self._commands = ctx.Queue()
        self._replies = ctx.Queue()
        self._proc: Any = None
        self._target: Callable[..., None] | None = None
        self._args: tuple[Any, ...] = ()
        self._generation = 0  # one per child: a dead child's reader no longer writes here
        self._ids = itertools.count(1)
        self._pending: dict[int, cf.Future] = {}
        self._lock = threading.Lock()
        self._restart_lock = threading.Lock()
        self._at_exit = False
        #: ``fn(batch)`` for every ``core.labdata.ticks.TickBatch`` the child sends (every loop
        #: tick, in order; on the reader thread: only enqueue there).
        self.tick_listeners: list[Callable[[Any], None]] = []

    def spawn(self, target: Callable[..., None], args: tuple[Any, ...]) -> None:
        """Start ``target(*args)`` in the child (``args`` include this handle's
        ``_commands`` / ``_replies`` queues where the child expects them; :meth:`restart`
        puts fresh ones in their places) and the reader."""
        self._target, self._args = target, args
        # Not a daemon: the child starts processes of its own. close() (also at exit) ends it.
        proc = self._ctx.Process(target=run_reporting, name=self.name,  # (a failure's
                                 args=(target, self._replies, *args))  # reason -> failure)
        proc.start()
        with self._lock:
            self._proc = proc
            generation = self._generation
        threading.Thread(target=self._read, args=(proc, self._replies, generation),
                         name=f"{self.name}-replies", daemon=True).start()
        if not self._at_exit:
            self._at_exit = True
            atexit.register(self.close)

    def view_age(self) -> float:
        """Seconds since the newest view arrived (``clock``); ``math.inf`` before the first."""
        at = self._view_at
        return math.inf if at is None else max(0.0, self.clock() - at)

    def restart(self, timeout: float = 5.0) -> None:
        """Replace the child by a new one with the same arguments; its loop starts disarmed.

        The old child is ended (asked to stop, then SIGTERM, then SIGKILL: it may be alive but
        silent), every pending Future fails with the reason, the queues are new (a killed
        child can leave a queue's lock held), and :attr:`view` / :attr:`failure` start over.

        Raises:
            RuntimeError: nothing was ever spawned (there are no arguments to repeat).
        """
        with self._restart_lock:
            if self._target is None:
                raise RuntimeError(f"the {self.name} process was never started")
            old_proc = self._proc
            reason = self.failure
            self._end_child(old_proc, timeout)
            reason = reason or exit_reason(old_proc.exitcode)
            why = f"the {self.name} process was restarted" + (f" ({reason})" if reason else "")
            old_commands, old_replies = self._commands, self._replies
            with self._lock:
                self._generation += 1  # the old reader stops writing here
                pending, self._pending = self._pending, {}
                self._commands, self._replies = self._ctx.Queue(), self._ctx.Queue()
                self.view, self._view_at, self._failure = None, None, None
            for fut in pending.values():
                if not fut.done():
                    fut.set_exception(RuntimeError(why))
            for q in (old_commands, old_replies):
                q.cancel_join_thread()  # a killed reader: never wait to flush into it
                q.close()
            swap = {id(old_commands): self._commands, id(old_replies): self._replies}
            args = tuple(swap.get(id(a), a) for a in self._args)
            self.spawn(self._target, args)

    def _end_child(self, proc: Any, timeout: float) -> None:
        """Ask ``proc`` to stop, then terminate, then kill it; always reap it."""
        if proc is None:
            return
        if proc.is_alive():
            try:
                self._commands.put(None)
            except (OSError, ValueError):
                pass
            proc.join(min(timeout, 2.0))
        if proc.is_alive():
            proc.terminate()
            proc.join(timeout)
        if proc.is_alive():
            proc.kill()
            proc.join(timeout)

    def _read(self, proc: Any, replies: Any, generation: int) -> None:
        while self._generation == generation:
            try:
                msg = replies.get(timeout=0.25)
            except queue.Empty:
                if not proc.is_alive():  # killed or crashed: the console says so
                    with self._lock:
                        if self._generation == generation:
                            self._failure = self._failure or exit_reason(proc.exitcode)
                    return
                continue
            except (EOFError, OSError, ValueError):
                return
            with self._lock:
                if self._generation != generation:
                    return  # restarted meanwhile: this child's news is history
            if msg[0] == "view":
                self.view = msg[1]
                self._view_at = self.clock()
            elif msg[0] == "ticks":
                for fn in list(self.tick_listeners):
                    fn(msg[1])
            elif msg[0] == "failed":
                self._failure = msg[1]
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
    def failure(self) -> str | None:
        """Why the child failed (its own report) or died (its exit), None while it runs."""
        failure = self._failure
        if failure is None:
            proc = self._proc
            if proc is not None and not proc.is_alive():
                failure = exit_reason(proc.exitcode)
        return failure

    @property
    def pid(self) -> int | None:
        """The current child's process id (None before :meth:`spawn`)."""
        proc = self._proc
        return None if proc is None else proc.pid

    @property
    def alive(self) -> bool:
        return self._proc is not None and self._proc.is_alive()

    def close(self, timeout: float = 5.0) -> None:
        """Stop the loop and the child process: asked to stop (``timeout`` s), then terminated,
        then killed (``timeout`` s each); the child has ended when this returns."""
        proc = self._proc
        if proc is None:
            return
        if proc.is_alive():
            self._commands.put(None)
            proc.join(timeout)
        if proc.is_alive():
            proc.terminate()
            proc.join(timeout)
        if proc.is_alive():
            proc.kill()
            proc.join(timeout)


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
        """The newest published :class:`~hw_bridge.interface.LinkHealth` (None: no link yet).

        While the loop process is dead, or its newest view is older than
        :data:`STALE_VIEW_S`, that health is not the link's any more: its state says why
        (``unknown: …``) and it is never armed."""
        view = self.ctl.view
        health = None if view is None else view.link
        if health is None:
            return None
        if not self.ctl.alive:
            why = self.ctl.failure or "the process ended"
            return dataclasses.replace(health, state=f"unknown: control loop not running ({why})",
                                       armed=False)
        age = self.ctl.view_age()
        if age > STALE_VIEW_S:
            return dataclasses.replace(
                health, state=f"unknown: no news from the control loop for {age:.1f} s",
                armed=False)
        return health


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
