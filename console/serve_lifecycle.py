"""serve.py's process lifecycle: a busy port, a signal while starting, a bounded shutdown.

* :func:`port_in_use`: viser silently moves to the next free port when ``--port`` is taken, so a
  second console (or a quick restart while the old one still holds the port) would serve
  somewhere nobody looks. serve.py checks first and refuses with exit code 2 unless
  ``--next-free-port`` is given (then it says loudly where it went).
* :class:`Lifecycle`: SIGTERM / SIGINT while starting end the process at once (exit 128 + n;
  the children follow by :mod:`hw_bridge.parent_watch`), instead of after a start-up that may
  take long; once serving, they ask for the ordinary shutdown. The children never see a
  terminal's Ctrl-C (SIGINT is blocked before they start: :meth:`Lifecycle.install`), so it
  ends quietly: one line from serve.py, no child tracebacks.
* :meth:`Lifecycle.shutdown` runs the shutdown steps in order but gives them ``budget`` s in all
  (a browser that never answers can hold viser's close handshake for seconds); past that it says
  so and exits - the control process and the emulator follow within 1 s and the device's
  watchdog stops the arm.
"""

from __future__ import annotations

import errno
import os
import signal
import socket
import sys
import threading
import time
from typing import Any, Callable, Iterable


def port_in_use(host: str, port: int) -> str | None:
    """Why ``host:port`` cannot be bound for serving, or None when it can.

    Binds the way the server will (``SO_REUSEADDR``, so a port in TIME_WAIT after a clean
    restart counts as free) and releases it at once.
    """
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                return f"port {port} on {host} is already in use (another console running?)"
            return f"cannot bind {host}:{port}: {exc.strerror or exc}"
    return None


class Lifecycle:
    """Signal handling from start-up to exit (see the module docstring)."""

    def __init__(self, say: Callable[[str], None] | None = None):
        self.done = threading.Event()
        self._say = say or (lambda text: print(f"serve.py: {text}", file=sys.stderr, flush=True))
        self._serving = False

    def install(self) -> "Lifecycle":
        """Handlers for SIGTERM and SIGINT (main thread only, before any thread or child).

        Ctrl-C in a terminal sends SIGINT to the whole foreground process group: serve.py and
        every child (control process, planner workers, device emulator), whose tracebacks and
        exit reports would then flood the terminal while the parent is stopping them in order.
        So SIGINT is blocked here, in the main thread: threads started later inherit the mask,
        and so does every child they start (the mask survives fork and exec), which therefore
        never sees the terminal's SIGINT and is stopped by this process (or, should it die, by
        ``hw_bridge.parent_watch``). This process takes it with ``sigwait`` on a thread of its
        own.
        """
        signal.signal(signal.SIGTERM, self._on_signal)
        signal.signal(signal.SIGINT, self._on_signal)  # (a thread started before this one)
        if hasattr(signal, "pthread_sigmask"):
            # multiprocessing starts its resource tracker on the first child and then unblocks
            # SIGINT in the thread that started it: start it now, before blocking.
            from multiprocessing import resource_tracker
            resource_tracker.ensure_running()
            signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
            threading.Thread(target=self._take_sigint, name="sigint", daemon=True).start()
        return self

    def _take_sigint(self) -> None:
        while True:
            self._on_signal(signal.sigwait({signal.SIGINT}), None)

    def _on_signal(self, signum: int, frame: Any) -> None:
        if self._serving:
            if not self.done.is_set():
                self._say(f"{signal.Signals(signum).name}: shutting down")
            self.done.set()
            return
        self._say(f"{signal.Signals(signum).name} while starting: exiting now")
        os._exit(128 + signum)

    def serving(self) -> None:
        """From now on a signal asks for :meth:`shutdown` (``done`` is set)."""
        self._serving = True

    def wait(self, poll: float = 0.5) -> None:
        """Serve until a signal arrives."""
        while not self.done.wait(poll):
            pass

    def shutdown(self, steps: Iterable[tuple[str, Callable[[], Any]]], budget: float = 5.0,
                 first_budget: float = 10.0, patient: int = 2) -> bool:
        """Run ``steps`` (name, function) in order in a helper thread: the first ``patient``
        (the arm's STOP, closing the hardware processes) get up to ``first_budget`` s, the rest
        ``budget`` s in all after them.

        The STOP and the hardware are waited for longer because they are what matters (on a
        loaded machine each took more than 2 s, and exiting before they finished left
        multiprocessing's semaphores to the resource tracker's "leaked" warning); the later
        steps close browsers' connections, which a browser that does not answer can hold
        forever. Their ``budget`` is 5 s: with no browser they take ~0.7 s, but 2 s was
        overrun on a loaded machine (the suite's workers on 2 cores), which then exited past
        the console's finalizers (the same "leaked" warning).

        Returns True when all finished; otherwise reports the step that hung and exits the
        process (code 0: a requested shutdown) without waiting further.
        """
        current = ["starting"]
        first_done = threading.Event()

        def run() -> None:
            for i, (name, fn) in enumerate(steps):
                current[0] = name
                try:
                    fn()
                except Exception as exc:  # noqa: BLE001 - shutting down: keep closing the rest
                    self._say(f"shutdown: {name} failed: {exc}")
                if i == patient - 1:
                    first_done.set()
            first_done.set()
            current[0] = ""

        t0 = time.monotonic()
        worker = threading.Thread(target=run, name="shutdown", daemon=True)
        worker.start()
        if first_done.wait(first_budget):
            worker.join(budget)
        if not worker.is_alive():
            return True
        self._say(f"shutdown: '{current[0]}' still running after {time.monotonic() - t0:.1f} s "
                  "(a browser not answering?); exiting without waiting")
        sys.stdout.flush()
        os._exit(0)
