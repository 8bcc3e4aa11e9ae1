"""A slow, looping demo motion of the commanded arm, stoppable like any other motion.

Used for demos, the lab browser tests and the load benchmark until the control loop's Execute
is wired into the console. It commands a smooth periodic configuration through
``StateStore.request`` with source ``"demo"`` from its own thread, every step limited like a jog
(no arm point faster than ``tip_speed``, 200 mm/s by default), and stops
when :meth:`DemoMotion.stop` runs (as a console service, ``ConsoleServices.demo``, the console
core's one STOP calls it: STOP, a lost lease, Release...) or when anyone else commands the arm.
"""

from __future__ import annotations

import threading
import time

import numpy as np
import numpy.typing as npt

from console.core.hold_to_run import limit_step
from console.core.model import ArmModel, ExtensibleModel, SoftArmModel
from console.core.state import StateStore

Array = npt.NDArray[np.float64]
SOURCE = "demo"


def demo_configuration(model: ArmModel, t: float, period: float = 10.0) -> Array:
    """The demo configuration at time ``t`` (s): a travelling bend, inside the limits."""
    w = 2 * np.pi / period
    if isinstance(model, SoftArmModel):
        k = 0.3 * model.robot.kappa_max
        i = np.arange(model.shape[0])
        return k * np.sin(w * t - 0.6 * i) * np.sin(0.5 * w * t + 0.3)
    if not isinstance(model, ExtensibleModel):
        raise TypeError(f"no demo motion for {type(model).__name__}")
    r = model.robot
    n = model.shape[0]
    q = np.zeros(model.shape)
    mid = 0.5 * (r.rack_min + r.rack_max) - r.L0
    for i in range(n):
        q[i, 2] = mid + 0.3 * mid * np.sin(w * t + i)
        q[i, 0] = 0.02 * np.sin(w * t - 0.8 * i)
        q[i, 1] = 0.02 * np.cos(w * t - 0.8 * i)
    return model.clamp(q)[0]


class DemoMotion:
    """Commands :func:`demo_configuration` at ``rate_hz`` until stopped."""

    def __init__(self, store: StateStore, rate_hz: float = 30.0, period: float = 10.0,
                 tip_speed: float = 0.2) -> None:
        self.store = store
        self.tip_speed = tip_speed
        self.period_s = 1.0 / rate_hz
        self.cycle = period
        self.steps = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()

    @property
    def running(self) -> bool:
        t = self._thread
        return t is not None and t.is_alive() and not self._stop.is_set()

    def start(self) -> None:
        with self._lock:
            if self.running:
                return
            self._stop = threading.Event()
            self._thread = threading.Thread(target=self._run, args=(self._stop,),
                                            name="console-demo", daemon=True)
            self._thread.start()

    def stop(self, reason: str = "") -> None:
        """Stop commanding (the console core's STOP: ``reason`` is only informative)."""
        with self._lock:
            self._stop.set()
            thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(1.0)

    def _run(self, stop: threading.Event) -> None:
        model = self.store.model
        t0 = time.perf_counter()
        q = np.array(self.store.command.q)  # start where the arm is and catch up, capped
        last_seq = -1
        next_t = t0
        while not stop.is_set():
            cmd = self.store.command
            if last_seq >= 0 and cmd.seq != last_seq:
                break  # someone else commanded the arm
            t = time.perf_counter() - t0
            goal = demo_configuration(model, t, self.cycle)
            q = limit_step(model, q, goal, self.tip_speed * self.period_s)
            last_seq = self.store.request(q, SOURCE).seq
            self.steps += 1
            next_t += self.period_s
            delay = next_t - time.perf_counter()
            if delay < 0:
                next_t = time.perf_counter()
            elif stop.wait(delay):
                break
        stop.set()
