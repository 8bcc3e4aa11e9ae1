"""Repeatability panel: open versus closed loop, N moves each to a point, as in Table I.

As in Hughes 2020, Table I ("reliability in positioning", +-19 mm one segment / +-29 mm two, on
the hardware, open loop): the arm retracts, moves to the rack lengths the tip IK gives for the
point, and the tip is measured once the motors settle; N times. Moves are joint-space straight
lines within the rack, motor and tip speed limits (and the rack and bending limits), streamed by
the :class:`~hw_bridge.extensible_runner.ExtensibleRunner`.

*Run* does the whole comparison (:func:`run_comparison`): N moves open loop, then N moves closed
loop on the tip (Hughes 2020's suggested closed loop, eq. 5 with the measured posture,
:mod:`core.control.closed_loop` through :mod:`hw_bridge.extensible_closed_loop`), with a progress
bar, and shows both side by side (mean tip error and +- spread in mm, with Table I's hardware
figures as reference rows) and a per-move scatter of the tip error
(:mod:`console.panels.extensible.repeatability_view`). The tip is measured by a tip sensor: ``serve.py
--slip F`` makes the emulator's racks slip on their pinions and stream a noisy tip. Without it
the panel says that there is nothing to compare (the emulated racks do not slip, so the open
loop already repeats; the encoders, the only measurement, cannot see slip) and *Run* measures the
open loop by the encoders.

The button only enqueues a request for the panel's worker thread; the worker queues moves on the
runner (the loop is the only writer to the hardware) and waits for them. A STOP (the console
core's) closes its :class:`StopGate` (no move is queued after it) and makes the runner hold.
"""

from __future__ import annotations

import dataclasses
import html
import queue
import threading
import time
from typing import Any, Callable

import numpy as np
import numpy.typing as npt
import viser

from console.panels.common.base import Panel
from console.panels.extensible.status import extensible_arm, extensible_runner
from console.panels.extensible.repeatability_view import (Comparison, RepeatabilityResult, comparison_html,
                                               error_plot_svg, sensor_note)
from console.core.console_core import ConsoleCore
from console.core.state import ArmState
from core.control.closed_loop import ClosedLoopSettings
from core.kinematics import delta as dk
from core.kinematics.delta_ik import solve_tip_ik
from core.robots import ExtensibleArm
from core.units import fmt_mm, mm_value
from hw_bridge.extensible_closed_loop import TipSensor, closed_loop_move
from hw_bridge.extensible_runner import ExtensibleRunner

Array = npt.NDArray[np.float64]
_AXES = ("x", "y", "z")
TIP_SAMPLES = 30
"""Tip frames averaged per measurement in a comparison (0.3 s at 100 Hz): the emulator's 2 mm
noise per axis becomes 0.37 mm, below the closed loop's 1 mm tolerance; with the sensor's 10
frames (0.63 mm per axis, about 1.1 mm in norm) every move corrected until the iteration cap."""


def run_repeatability(runner: ExtensibleRunner, robot: ExtensibleArm, point: npt.ArrayLike,
                      n: int, *, on_progress: Callable[[int, str], None] | None = None,
                      should_stop: Callable[[], bool] = lambda: False,
                      timeout: float = 120.0, tip: TipSensor | None = None,
                      closed_loop: bool = False,
                      settings: ClosedLoopSettings = ClosedLoopSettings(),
                      on_move: Callable[[RepeatabilityResult], None] | None = None,
                      samples: int | None = None) -> RepeatabilityResult:
    """Retract, move to ``point``, measure; ``n`` times. Blocks (run it on a worker thread).

    Without ``tip`` the tip is measured from the encoders. With a ``tip`` sensor it is measured
    by the sensor, and ``closed_loop`` corrects each move to the point on it with ``settings``
    (:func:`hw_bridge.extensible_closed_loop.closed_loop_move`; otherwise the move is open loop).
    ``on_move`` gets the result so far after every measured move; ``samples``: tip frames
    averaged per measurement (default: the sensor's).

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
    corrections = 0
    t0 = time.monotonic()
    progress = on_progress or (lambda i, s: None)

    def done(reached: Array, message: str = "") -> RepeatabilityResult:
        return RepeatabilityResult(p, reached, n, message,
                                   "encoders" if tip is None else "tip sensor", closed_loop,
                                   seconds=time.monotonic() - t0, corrections=corrections)
    for i in range(n):
        for goal, label in ((home, "retract"), (ik.lengths, "to point")):
            if should_stop():
                return done(np.array(tips).reshape(-1, 3), message="stopped")
            progress(i, f"{label} {i + 1}/{n}")
            try:
                if tip is not None and goal is ik.lengths:
                    used = settings if closed_loop else dataclasses.replace(settings,
                                                                            iterations=0)
                    moved = closed_loop_move(runner, p, tip, settings=used, timeout=timeout,
                                             samples=samples)
                    reached, corrections = moved.measured[-1], corrections + moved.corrections
                    break
                result = runner.wait(runner.move_to(goal, f"{label} {i + 1}/{n}"), timeout)
            except (RuntimeError, TimeoutError) as exc:
                return done(np.array(tips).reshape(-1, 3), message=str(exc))
            if result is None or not result.ok:
                why = "timed out" if result is None else result.message
                return done(np.array(tips).reshape(-1, 3), message=why)
            reached = result.final_tip
        tips.append(np.asarray(reached, dtype=float))
        if on_move is not None:
            on_move(done(np.array(tips)))
    progress(n, "done")
    return done(np.array(tips))


class StopGate:
    """A runner whose moves a STOP cuts off: a move asked for under an older stop generation of
    the console core never reaches the runner.

    The check and the queueing of a move happen under the core's lock
    (:meth:`console.core.console_core.ConsoleCore.run_if_current`), as does the core's STOP, so
    no move is ever queued behind a STOP (the core makes the runner hold). It offers what
    :func:`run_repeatability` uses of a runner.
    """

    def __init__(self, runner: Any, core: ConsoleCore, generation: int) -> None:
        self.runner = runner
        self.robot = runner.robot
        self.core = core
        self.generation = generation

    @property
    def closed(self) -> bool:
        return self.core.stop_generation != self.generation

    def start(self) -> Any:
        return self.runner.start()

    def move_to(self, lengths: npt.ArrayLike, label: str = "move") -> int:
        """The runner's move, unless a STOP came first (then :class:`MotionStopped`,
        a RuntimeError "stopped")."""
        return self.core.run_if_current(self.generation,
                                        lambda: self.runner.move_to(lengths, label))

    def wait(self, job_id: int, timeout: float | None = None) -> Any:
        return self.runner.wait(job_id, timeout)


def run_comparison(runner: Any, robot: ExtensibleArm, point: npt.ArrayLike, n: int,
                   tip: TipSensor | None, *,
                   on_update: Callable[[Comparison], None] = lambda c: None,
                   on_progress: Callable[[str], None] = lambda text: None,
                   should_stop: Callable[[], bool] = lambda: False,
                   settings: ClosedLoopSettings = ClosedLoopSettings(),
                   samples: int | None = TIP_SAMPLES, timeout: float = 120.0) -> Comparison:
    """``n`` moves open loop to ``point``, then ``n`` closed loop on ``tip``; blocks.

    Without a tip sensor only the open loop runs, measured by the encoders (a loop closed on
    them cannot see slip, so there is nothing to compare). ``on_update`` gets the comparison
    after every measured move and at the end, ``on_progress`` what moves now. Both loops
    measure with ``samples`` tip frames (:data:`TIP_SAMPLES`). A loop that ended early (STOP, a failed move) ends
    the run with its message.

    Raises:
        ValueError: a bad point or ``n``, or a point the arm cannot reach (nothing moves).
    """
    c = Comparison(np.asarray(point, dtype=float), n, robot.n_segments, tip is not None)
    loops = ("open", "closed") if tip is not None else ("open",)
    for loop in loops:
        def moved(r: RepeatabilityResult, loop: str = loop) -> None:
            on_update(dataclasses.replace(c, **{loop: r}))
        def stage(i: int, text: str, loop: str = loop) -> None:
            on_progress(f"{loop} loop: {text}")
        r = run_repeatability(runner, robot, c.point, n, tip=tip, closed_loop=loop == "closed",
                              settings=settings, should_stop=should_stop, on_move=moved,
                              on_progress=stage, timeout=timeout, samples=samples)
        c = dataclasses.replace(c, **{loop: r})
        if r.message:
            c = dataclasses.replace(c, message=f"{loop} loop: {r.message}")
            break
    c = dataclasses.replace(c, finished=True)
    on_update(c)
    return c


@dataclasses.dataclass(frozen=True)
class RunRequest:
    """What the button asks the worker for: ``n`` moves per loop to ``point`` (m); ``stops``:
    the console core's stop generation when it was asked (a STOP since cancels it)."""

    point: Array
    n: int
    stops: int


class RepeatabilityPanel(Panel):
    """Point, moves per loop, Run (open then closed loop), progress, table and plot."""

    title = "Repeatability"
    tab = "Experiments"
    order = 40.0
    kinds = ("delta",)

    def build(self) -> None:
        sensor = self.app.services.tip_sensor is not None
        self.note = self.gui.add_html(sensor_note(sensor))
        tip = self._tip()
        self.inputs = [self.gui.add_number(f"Point {a} (mm)", mm_value(v), step=0.1)
                       for a, v in zip(_AXES, tip)]
        self.use_tip = self.gui.add_button("Point ← current tip")
        self.count = self.gui.add_number("Moves per loop", 5, min=1, max=50, step=1,
                                         hint="Table I: five moves from retracted per point.")
        self.run_btn = self.gui.add_button(
            "Run open vs closed loop" if sensor else "Run open loop (encoders)", color="green",
            icon=viser.Icon.PLAYER_PLAY,
            hint=("N moves open loop, then N closed loop on the tip sensor (eq. 5 with the "
                  "measured tip). STOP ends the run." if sensor else
                  "No tip sensor: serve.py --slip F starts the emulator's slipping racks and tip "
                  "stream, which a closed loop can correct. The encoders cannot see slip."))
        self.progress = self.gui.add_progress_bar(0.0, color="blue")
        self.status = self.gui.add_html("")
        self.table = self.gui.add_html("")
        self.plot = self.gui.add_html("")
        self._requests: queue.SimpleQueue[RunRequest | None] = queue.SimpleQueue()
        self._busy = threading.Event()
        self.use_tip.on_click(lambda _: self._use_tip())
        self.run_btn.on_click(self.operator_only(lambda _: self._request(),
                                                 "run a repeatability test"))
        threading.Thread(target=self._serve, daemon=True, name="repeatability").start()

    def _use_tip(self) -> None:
        for h, v in zip(self.inputs, self._tip()):
            h.value = mm_value(v)

    def _tip(self) -> Array:
        robot: Any = self.app.robot
        return dk.tip_position(robot, np.asarray(self.app.store.command.q))

    def _request(self) -> None:
        """Button: enqueue a run for the worker (nothing else)."""
        if self._busy.is_set():
            self._say("⚠ A run is in progress: STOP ends it.")
            return
        self._busy.set()
        self._requests.put(RunRequest(np.array([float(h.value) for h in self.inputs]) / 1e3,
                                      int(self.count.value), self.app.core.stop_generation))

    def _serve(self) -> None:
        """Worker: one run per request, one at a time."""
        while (req := self._requests.get()) is not None:
            try:
                self._run(req)
            except Exception as exc:  # noqa: BLE001 - shown, and the worker goes on
                self._say(f"⚠ {exc}")
            finally:
                self._busy.clear()

    def close(self) -> None:
        """End the worker (after the run in progress, which this stops)."""
        if self._busy.is_set():
            self.app.core.stop_motion("the Repeatability panel closed")
        self._requests.put(None)
        super().close()

    def _run(self, req: RunRequest) -> None:
        gate = StopGate(extensible_runner(self.app), self.app.core, req.stops)  # (a STOP
        # between the click and now: closed already)
        tip = self.app.services.tip_sensor
        self.progress.value = 0.0
        self.plot.content = ""
        # The new run's empty table at once (the last run's reason must not stand under it).
        self.table.content = comparison_html(Comparison(
            np.asarray(req.point, dtype=float), req.n, self.app.robot.n_segments, tip is not None))
        self._say("Running…")

        def show(c: Comparison) -> None:
            self.progress.value = round(100.0 * c.done / c.total, 1)
            if c.finished:  # before the table: its data-state says the run is over
                self._say("Stopped." if gate.closed else ("Done." if not c.message else
                                                           f"⚠ {c.message}"))
            self.plot.content = error_plot_svg(c)
            self.table.content = comparison_html(c)
        try:
            run_comparison(gate, extensible_arm(self.app), req.point, req.n, tip,
                           on_update=show, should_stop=lambda: gate.closed,
                           on_progress=lambda text: self._say(f"Running {text}…"))
        except ValueError as exc:
            self._say(f"⚠ {exc}")

    def _say(self, text: str) -> None:
        self.status.content = (f'<div data-testid="rep-status" style="font-size:0.85em">'
                               f"{html.escape(text)}</div>")

    def on_state(self, state: ArmState) -> None:
        """Nothing per frame: the worker reports progress and results itself."""
