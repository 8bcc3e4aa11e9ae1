"""Headless recording of trials: ``python -m core.control.trials ... --record PATH.mcap``.

Each trial runs as in :func:`core.control.trials.run_trials` (same seeds: ``seed * 1000 + i``;
worker processes or in-process) with a :class:`TrialSampler` watching every loop tick; the
trials are then written one after the other into one MCAP file through the same writer and
channels as the console's recordings (:class:`core.labdata.mcap_file.McapLog`): the measured
and reference curvature, the 3D scene, the object, control phase, loop timing and faults, every
loop tick on ``/control/ticks`` (:mod:`core.labdata.ticks`, without timing), with an
operator-action marker where each trial starts and ends (its result). Log time is the
simulated clock, laid out from the wall-clock start of the run, trials 1 s apart.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from core.control.planner_spec import DEFAULT_PLANNER
from core.labdata.channels import ArmGeometry, robot_description
from core.labdata.mcap_file import McapLog
from core.labdata.telemetry import LoopRecords, plan_data
from core.labdata.ticks import SoftArmTicks, TickRing
from core.robots import load

GAP_S = 1.0
TICK_BATCH = 500  # ticks per ``ticks`` record (5 s of simulated time)


@dataclasses.dataclass(frozen=True)
class _Tick:
    """A loop snapshot made from bare telemetry (a loop that hands its ``until`` only that)."""

    tick: int
    t: float
    control: Any


class TrialSampler:
    """Loop observer: phase changes and faults at every tick; configuration, loop timing and
    the object (when it moved > 1 mm) at ``hz`` (the loop runs at 100 Hz); every plan the state
    machine gets (:meth:`on_plan`, called by ``core.control.trials.run_trial``).

    It is called with each tick's ``hw_bridge.loop.LoopSnapshot``, or with each tick's
    ``core.control.stack.Telemetry`` (or None) by a loop that passes only that: its loop timing
    is then the simulated period (10 ms) and, as ``work_ms``, the wall time the last simulated
    tick took on this computer (simulation, control and this recording).
    """

    def __init__(self, hz: float = 10.0, period_s: float = 0.01, n_segments: int = 6) -> None:
        self.every = max(1, round(1.0 / (hz * period_s)))
        self.period_s = period_s
        self._loop = LoopRecords(with_state=True)
        self._obj: np.ndarray | None = None
        self._ticks = 0
        self._ring = TickRing(SoftArmTicks(n_segments), TICK_BATCH + 1)
        self.records: list[dict[str, Any]] = []
        self._t = 0.0  # loop time of the newest tick
        self._wall: float | None = None  # perf_counter at the previous tick

    def on_plan(self, plan: Any, refusal: str | None) -> None:
        """A plan made for the state machine (None and why: refused), as a ``plan`` record."""
        self.flush()
        self.records.append({"kind": "plan", "t": self._t, "data": plan_data(plan, refusal)})

    def __call__(self, snap: Any) -> bool:
        self._ticks += 1
        now = time.perf_counter()
        work_ms = None if self._wall is None else (now - self._wall) * 1e3
        self._wall = now
        bare = snap is not None and not hasattr(snap, "control")
        if bare:  # bare telemetry
            snap = _Tick(self._ticks, float(snap.t), snap)
        self._tick_row(snap)
        if snap is None:
            return False
        self._t = float(snap.t)
        sample = snap.tick % self.every == 0
        if bare and sample and work_ms is not None:  # loop timing on the simulated clock
            self.flush()
            self.records.append({"kind": "timing", "t": self._t, "data": {
                "tick": int(snap.tick), "loop_t": self._t, "period_ms": self.period_s * 1e3,
                "work_ms": work_ms, "overruns": 0}})
        for rec in self._loop.records(snap):
            if sample or rec["kind"] in ("phase", "fault"):
                rec["t"] = float(snap.t)
                self.flush()  # the ticks up to this one first: log times never decrease
                self.records.append(rec)
        c = snap.control
        if sample and c is not None and c.object_xy is not None:
            xy = np.asarray(c.object_xy, dtype=float)
            if self._obj is None or float(np.hypot(*(xy - self._obj))) > 0.001:
                self._obj = xy
                self.flush()
                self.records.append({"kind": "objects", "t": float(snap.t), "data": {
                    "objects": [{"name": "object", "x": float(xy[0]), "y": float(xy[1]),
                                 "r": None}]}})
        return False  # never ends the run

    def _tick_row(self, snap: Any) -> None:
        """Every tick on the tick channel (no timing: the clock is simulated)."""
        c = None if snap is None else snap.control
        t = (self._ticks - 1) * self.period_s if snap is None else float(snap.t)
        self._ring.add(self._ticks, t, None, getattr(c, "commands", None), c)
        if self._ring.written % TICK_BATCH == 0:
            self.flush()

    def flush(self) -> None:
        """Move the ticks not yet in :attr:`records` there (one ``ticks`` record)."""
        batch = self._ring.drain()
        if batch is not None:
            self.records.append({"kind": "ticks", "t": float(batch.rows[0, 1]), "batch": batch})


def _recorded_trial(job: tuple) -> tuple[Any, list[dict[str, Any]]]:
    from core.control import trials

    robot_src, obj, seed, label, planner, limit, overrides, hz = job
    robot = load(robot_src)
    sampler = TrialSampler(hz, n_segments=robot.n_segments)
    result = trials.run_trial(robot, obj, seed, label=label, planner=planner,
                              time_limit_s=limit, sim_overrides=overrides, observe=sampler)
    sampler.flush()
    return result, sampler.records


def record_trials(path: str | Path, robot_src: str,
                  objects: Sequence[tuple[str, Sequence[float]]], repeats: int, seed: int, *,
                  map_fn: Callable[..., Any] = map, planner: str = DEFAULT_PLANNER,
                  time_limit_s: float = 150.0, sim_overrides: dict[str, Any] | None = None,
                  progress: Callable[[int, int, Any], None] | None = None,
                  hz: float = 10.0) -> list[Any]:
    """Run and record the trials into ``path`` (must not exist); returns the results in order.

    ``map_fn`` runs the jobs (builtin ``map``, or a process pool's ``map`` from the command
    line: core owns no pool), in job order.

    Raises:
        FileExistsError: ``path`` exists (checked before any trial runs).
    """
    path = Path(path)
    if path.exists():
        raise FileExistsError(f"{path} exists; choose a new file name")
    robot = load(robot_src)
    jobs = [(robot_src, list(map(float, obj)), seed * 1000 + i, label, planner, time_limit_s,
             sim_overrides, hz)
            for i, (label, obj) in enumerate((lab, o) for lab, o in objects for _ in range(repeats))]
    done: list[tuple[Any, list[dict[str, Any]]]] = []
    start_ns = time.time_ns()
    for item in map_fn(_recorded_trial, jobs):
        done.append(item)
        if progress:
            progress(len(done), len(jobs), item[0])
    header = {"robot": robot.name, "robot_kind": robot.kind,
              "shape": [robot.n_segments], "by": "python -m core.control.trials",
              "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "trials": len(jobs),
              "clock": "simulated"}
    offset = 0.0
    with McapLog(path, header, start_ns, ArmGeometry(robot)) as log:
        log.record({"kind": "robot", "who": "trials", "t": 0.0,
                    "data": robot_description(robot)})
        for i, (result, records) in enumerate(done):
            x, y, r = result.object
            who = "trials"
            log.record({"kind": "action", "who": who, "t": offset,
                        "what": f"trial {i + 1}/{len(jobs)} start: spot {result.label or '-'} "
                                f"object ({x:.3f}, {y:.3f}) m r {r * 1000:.1f} mm, "
                                f"seed {result.seed}"})
            log.record({"kind": "objects", "who": who, "t": offset, "data": {
                "objects": [{"name": result.label or f"#{i + 1}", "x": x, "y": y, "r": r}]}})
            for rec in records:
                if rec["kind"] == "ticks":  # every loop tick, at its simulated time
                    log.ticks(rec["batch"], start_ns + round(offset * 1e9))
                    continue
                if rec["kind"] == "objects":  # the object as it moves: its radius is known
                    rec["data"]["objects"][0]["r"] = r
                log.record({**rec, "t": offset + rec["t"]})
            end = offset + float(result.sim_s)
            verdict = "success" if result.success else f"FAILED: {result.failure}"
            log.record({"kind": "action", "who": who, "t": end,
                        "what": f"trial {i + 1}/{len(jobs)} end: {verdict}"})
            offset = end + GAP_S
    return [result for result, _ in done]
