"""Repeatability panel: move to a point from the retracted pose N times and report the spread.

As in Hughes 2020, Table I ("reliability in positioning", +-19 mm / +-29 mm): the arm retracts,
moves to the rack lengths the tip IK gives for the point, and the tip is measured (from the
encoders, through forward kinematics) once the motors settle; N times. Per axis the panel shows
the mean, the spread +-(max - min) / 2, the standard deviation and the mean's offset from the
point. Moves are joint-space straight lines within the rack, motor and tip speed limits (and the
rack and bending limits), streamed by the :class:`~hw_bridge.extensible_runner.ExtensibleRunner`.
On the emulator the encoders are exact, so the spread is only encoder quantisation; a real arm
adds its backlash and friction.

With a tip sensor (``serve.py --slip F``: the emulator's racks slip on their pinions and it
streams a noisy tip measurement, :mod:`hw_bridge.extensible_closed_loop`), the tip is measured by
that sensor instead -- the encoders cannot see slip -- and the *Closed loop on the tip* checkbox
corrects every move to the point on it (Hughes 2020's suggested closed loop, eq. 5 with the
measured posture, :mod:`core.control.closed_loop`). Open and closed loop can then be compared on
the same arm (``python -m core.control.repeatability`` does the same study offline).
"""

from __future__ import annotations

import functools
import html
import threading
from typing import Any, Callable

import numpy as np
import numpy.typing as npt
import viser

from console.panels.base import Panel
from console.panels.paths import extensible_runner
from console.panels.repeatability_view import RepeatabilityResult, result_html
from console.state import ArmState
from core.units import fmt_mm, mm_value
from core.control.closed_loop import ClosedLoopSettings
from core.kinematics import delta as dk
from core.kinematics.delta_ik import solve_tip_ik
from core.robots import ExtensibleArm
from hw_bridge.extensible_closed_loop import TipSensor, closed_loop_move
from hw_bridge.extensible_runner import ExtensibleRunner

Array = npt.NDArray[np.float64]
_AXES = ("x", "y", "z")


def run_repeatability(runner: ExtensibleRunner, robot: ExtensibleArm, point: npt.ArrayLike,
                      n: int, *, on_progress: Callable[[int, str], None] | None = None,
                      should_stop: Callable[[], bool] = lambda: False,
                      timeout: float = 120.0, tip: TipSensor | None = None,
                      closed_loop: bool = False) -> RepeatabilityResult:
    """Retract, move to ``point``, measure; ``n`` times. Blocks (run it on a worker thread).

    Without ``tip`` the tip is measured from the encoders. With a ``tip`` sensor it is measured
    by the sensor, and ``closed_loop`` corrects each move to the point on it
    (:func:`hw_bridge.extensible_closed_loop.closed_loop_move`; otherwise the move is open loop).

    Raises:
        ValueError: ``n`` < 1, a bad point, a point the arm cannot reach, or ``closed_loop``
            without a tip sensor (nothing moves).
    """
    p = np.asarray(point, dtype=float)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise ValueError(f"point must be 3 finite numbers (m), got {point!r}")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"repetitions must be an integer >= 1, got {n!r}")
    if closed_loop and tip is None:
        raise ValueError("closed loop needs a tip sensor (serve.py --slip F starts the "
                         "emulator's tip stream)")
    ik = solve_tip_ik(robot, p)
    if not ik.reachable:
        raise ValueError(f"point is unreachable: the closest feasible tip is "
                         f"{fmt_mm(ik.error, 1)} mm away")
    home = dk.robot_rack_lengths(robot, np.zeros((robot.n_segments, 3)))
    runner.start()
    tips: list[Array] = []
    progress = on_progress or (lambda i, s: None)
    done = functools.partial(RepeatabilityResult, p, requested=n,
                             source="encoders" if tip is None else "tip sensor",
                             closed_loop=closed_loop)
    for i in range(n):
        for goal, label in ((home, "retract"), (ik.lengths, "to point")):
            if should_stop():
                return done(np.array(tips).reshape(-1, 3), message="stopped")
            progress(i, f"{label} {i + 1}/{n}")
            if tip is not None and goal is ik.lengths:
                settings = ClosedLoopSettings() if closed_loop else ClosedLoopSettings(0)
                try:
                    reached = closed_loop_move(runner, p, tip, settings=settings,  # type: ignore[arg-type]
                                               timeout=timeout).measured[-1]
                except (RuntimeError, TimeoutError) as exc:
                    return done(np.array(tips).reshape(-1, 3), message=str(exc))
                break
            result = runner.wait(runner.move_to(goal, f"{label} {i + 1}/{n}"), timeout)
            if result is None or not result.ok:
                why = "timed out" if result is None else result.message
                return done(np.array(tips).reshape(-1, 3), message=why)
            reached = result.final_tip
        tips.append(np.asarray(reached, dtype=float))
    progress(n, "done")
    return done(np.array(tips))


class RepeatabilityPanel(Panel):
    """Point, repetitions, run / stop, progress and the per-axis spread."""

    title = "Repeatability"
    tab = "Experiments"
    order = 40.0
    kinds = ("delta",)

    def build(self) -> None:
        tip = self._tip()
        self.inputs = [self.gui.add_number(f"Point {a} (mm)", mm_value(v), step=0.1)
                       for a, v in zip(_AXES, tip)]
        self.use_tip = self.gui.add_button("Point ← current tip")
        self.count = self.gui.add_number("Repetitions", 5, min=1, max=50, step=1,
                                         hint="Table I: five moves per point.")
        sensor = self.app.services.tip_sensor
        self.closed = self.gui.add_checkbox(
            "Closed loop on the tip", False, disabled=sensor is None,
            hint=("Correct every move to the point on the tip sensor (eq. 5 with the measured "
                  "tip); off: open loop, measured by the tip sensor." if sensor is not None else
                  "Needs a tip sensor: serve.py --slip F (the emulator's slipping racks and "
                  "tip stream). The encoders cannot see slip."))
        self.run_btn = self.gui.add_button("Run", color="green", icon=viser.Icon.PLAYER_PLAY)
        self.progress = self.gui.add_progress_bar(0.0, color="blue")
        self.status = self.gui.add_html("")
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.use_tip.on_click(lambda _: self._use_tip())
        self.run_btn.on_click(self.operator_only(lambda _: self._start(),
                                                 "run a repeatability test"))
        self.app.add_stop_hook(self._halt)

    def _use_tip(self) -> None:
        for h, v in zip(self.inputs, self._tip()):
            h.value = mm_value(v)

    def _tip(self) -> Array:
        robot: Any = self.app.robot
        return dk.tip_position(robot, np.asarray(self.app.store.command.q))

    def _start(self) -> None:
        if self._thread is not None and self._thread.is_alive():
            self._say("⚠ A run is in progress: stop it first.")
            return
        point = np.array([float(h.value) for h in self.inputs]) / 1e3
        n = int(self.count.value)
        closed = bool(self.closed.value) and self.app.services.tip_sensor is not None
        self._stop.clear()
        self._thread = threading.Thread(target=self._work, args=(point, n, closed), daemon=True,
                                        name="repeatability")
        self._thread.start()

    def _halt(self, reason: str = "") -> None:
        """Stop hook: end the run after the current move, which the runner stops now."""
        self._stop.set()
        runner = self.app.services.extensible_runner
        if runner is not None and runner.started:
            runner.stop()

    def _work(self, point: Array, n: int, closed: bool = False) -> None:
        runner = extensible_runner(self.app)
        self.progress.value = 0.0

        def progress(i: int, text: str) -> None:
            self.progress.value = round(100.0 * i / n, 1)
            self._say(f"Running: {text}…")
        try:
            result = run_repeatability(runner, self.app.robot, point, n,  # type: ignore[arg-type]
                                       on_progress=progress, should_stop=self._stop.is_set,
                                       tip=self.app.services.tip_sensor, closed_loop=closed)
        except ValueError as exc:
            self._say(f"⚠ {exc}")
            return
        self.status.content = result_html(result)

    def _say(self, text: str) -> None:
        self.status.content = (f'<div data-testid="rep-status" style="font-size:0.85em">'
                               f"{html.escape(text)}</div>")

    def on_state(self, state: ArmState) -> None:
        """Nothing per frame: the worker reports progress and results itself."""
