"""What the extensible arm's runner streams and reports: encoder maths, joint moves, job records.

Pure helpers and immutable records shared by :mod:`hw_bridge.extensible_streamer` (the loop's
per-tick logic) and :mod:`hw_bridge.extensible_runner` (the thread and its API, which re-exports
them): :func:`home_counts` and :func:`measure` (encoders -> racks, Delta, tip), :func:`joint_move`
(a straight, limit-respecting line in rack space), the console link (:class:`PoseLink`,
:class:`StoreLink`) and the job / snapshot records.

Encoder zero. Incremental encoders read 0 where the board powered up, which is the retracted
(homed) pose: demands are ``U^-1 L`` counts minus those of the retracted pose (:func:`home_counts`).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from core.kinematics import delta as dk
from core.planning.paths import MotionPath
from core.robots import ExtensibleArm

Array = npt.NDArray[np.float64]
Counts = npt.NDArray[np.int64]


ARM_FIRST = "arm first (Arm device): connecting never arms the arm"


def home_counts(robot: ExtensibleArm) -> Counts:
    """Absolute motor counts ``U^-1 L`` of the retracted pose, where the encoders read 0."""
    retracted = dk.robot_rack_lengths(robot, np.zeros((robot.n_segments, 3)))
    return dk.motor_counts_from_lengths(robot, retracted)


def mid_range_counts(robot: ExtensibleArm) -> Counts:
    """Encoder counts (3n,) of the console's start pose (straight, racks at mid-range:
    :func:`core.kinematics.delta.mid_range_delta`), where the emulated and mock devices start."""
    lengths = dk.robot_rack_lengths(robot, dk.mid_range_delta(robot))
    return dk.motor_counts_from_lengths(robot, lengths) - home_counts(robot)


def measure(robot: ExtensibleArm, encoders: npt.ArrayLike,
            home: Counts) -> tuple[Array, Array, Array]:
    """Encoder counts (3n,) -> rack lengths (n, 3), Delta (n, 3) and tip (3,)."""
    lengths = dk.lengths_from_motor_counts(robot, np.asarray(encoders, dtype=float) + home)
    delta = dk.delta_from_actuators(lengths, robot.phi, robot.L0)
    return lengths, delta, dk.tip_position(robot, delta)


def planned_motor_speed(robot: ExtensibleArm, rate_hz: float, margin: float) -> float:
    """Motor speed to plan for (m/s): ``margin`` of ``motor_speed``, and one encoder count per
    sample below it, so demands rounded to counts still obey the limit (as in
    :func:`core.planning.paths.timed_path`)."""
    return min(robot.motor_speed * margin, robot.motor_speed - rate_hz / robot.counts_per_metre)


def joint_move(robot: ExtensibleArm, start: npt.ArrayLike, goal: npt.ArrayLike, *,
               rate_hz: float = 100.0, margin: float = 0.98) -> MotionPath:
    """Straight line in rack space from rack lengths ``start`` to ``goal`` (each (n, 3)).

    Both ends are first moved into the limits (:func:`core.kinematics.delta.limit_rack_lengths`:
    rack box and bending limit). That set is convex, so every sample is within the limits.
    Timed like :func:`core.planning.paths.plan_path`: no rack faster than ``rack_speed``, no
    motor (m = U^-1 L: a proximal motor moves by the difference of two racks) faster than
    ``motor_speed``, and the tip (over a fine sub-sampling) no faster than ``tip_speed``, all
    scaled by ``margin``. The targets are the tips reached (errors 0).
    """
    shape = (robot.n_segments, 3)
    a, b = np.asarray(start, dtype=float), np.asarray(goal, dtype=float)
    if a.shape != shape or b.shape != shape:
        raise ValueError(f"start and goal must be rack lengths of shape {shape}")
    a, b = dk.limit_rack_lengths(robot, a), dk.limit_rack_lengths(robot, b)
    travel = float(np.abs(b - a).max())
    m = max(8, math.ceil(travel / 5e-4))
    s = np.linspace(0.0, 1.0, m + 1)
    sub = a + (b - a) * s[:, None, None]
    tips = dk.tip_position(robot, dk.delta_from_actuators(sub, robot.phi, robot.L0))
    racks = np.abs(np.diff(sub, axis=0)).reshape(m, -1).max(axis=1)
    motors = np.abs(np.diff(dk.motors_from_lengths(sub), axis=0)).reshape(m, -1).max(axis=1)
    dt = np.maximum.reduce([racks / (robot.rack_speed * margin),
                            motors / planned_motor_speed(robot, rate_hz, margin),
                            np.linalg.norm(np.diff(tips, axis=0), axis=1)
                            / (robot.tip_speed * margin)])
    t_sub = np.concatenate([[0.0], np.cumsum(dt)])
    count = math.ceil(t_sub[-1] * rate_hz - 1e-9) + 1
    times = np.arange(count) / rate_hz
    lengths = a + (b - a) * np.interp(times, t_sub, s)[:, None, None]
    deltas = dk.delta_from_actuators(lengths, robot.phi, robot.L0)
    reached = dk.tip_position(robot, deltas)
    return MotionPath(times=times, targets=reached, tips=reached, deltas=deltas, lengths=lengths,
                      motor_counts=dk.motor_counts_from_lengths(robot, lengths),
                      errors=np.zeros(count), rate_hz=rate_hz, jumps=0)


def concat_paths(a: MotionPath, b: MotionPath) -> MotionPath:
    """``a`` then ``b`` (b's first sample follows a's last one period later)."""
    dt = 1.0 / a.rate_hz
    cat = lambda x, y: np.concatenate([x, y])  # noqa: E731
    return MotionPath(times=cat(a.times, b.times + a.times[-1] + dt),
                      targets=cat(a.targets, b.targets), tips=cat(a.tips, b.tips),
                      deltas=cat(a.deltas, b.deltas), lengths=cat(a.lengths, b.lengths),
                      motor_counts=cat(a.motor_counts, b.motor_counts),
                      errors=cat(a.errors, b.errors), rate_hz=a.rate_hz, jumps=a.jumps + b.jumps)


class PoseLink(Protocol):
    """How the runner talks to an operator console (optional).

    ``setpoint()``: newest commanded posture (n, 3) and its sequence number (followed while
    idle); ``measured(delta)``: show the measured posture (while a job runs, or always if
    ``always_report``); ``settled(delta)``: a job ended there, make it the command (returns its
    sequence number).
    """

    always_report: bool

    def setpoint(self) -> tuple[int, Array] | None: ...

    def measured(self, delta: Array) -> None: ...

    def settled(self, delta: Array) -> int: ...


class StoreLink:
    """:class:`PoseLink` onto a console ``StateStore`` (duck-typed: command, report, request)."""

    def __init__(self, store: Any) -> None:
        self.store = store
        self.always_report = not getattr(store, "mirror_commands", True)

    def setpoint(self) -> tuple[int, Array]:
        cmd = self.store.command
        return cmd.seq, np.asarray(cmd.q)

    def measured(self, delta: Array) -> None:
        self.store.report(delta, "runner")

    def settled(self, delta: Array) -> int:
        return self.store.request(delta, "runner").seq


@dataclasses.dataclass
class JobTrace:
    """Per-sample record of one job; the loop writes index i before publishing ``count > i``."""

    times: Array             # (K,) s
    targets: Array           # (K, 3) tip targets
    commanded: Array         # (K, 3) tips of the demanded postures
    measured: Array          # (K, 3) tips from the encoders (NaN until written)


@dataclasses.dataclass(frozen=True)
class JobResult:
    """How a job ended. ``error``: measured final tip to the final target (m)."""

    job_id: int
    label: str
    ok: bool
    message: str
    final_tip: Array | None
    final_target: Array | None
    error: float | None


@dataclasses.dataclass(frozen=True)
class RunnerSnapshot:
    """What the UI reads; replaced (never mutated) every tick.

    ``state``: disconnected (no link) | disarmed (link configured, telemetry only: the measured
    pose updates, nothing is commanded) | holding | following | running | settling | fault.
    """

    state: str
    tick: int = 0
    job_id: int = 0
    label: str = ""
    sample: int = 0
    n_samples: int = 0
    measured_delta: Array | None = None
    measured_tip: Array | None = None
    fault: str | None = None
    message: str = ""
    trace: JobTrace | None = None
    trace_count: int = 0
    last_result: JobResult | None = None

    @property
    def progress(self) -> float:
        """Fraction of the job's samples streamed (1 once settled)."""
        return 0.0 if self.n_samples == 0 else min(1.0, self.sample / max(1, self.n_samples - 1))

    @property
    def busy(self) -> bool:
        return self.state in ("running", "settling")


@dataclasses.dataclass
class Job:
    """A job being streamed (loop thread only)."""

    job_id: int
    label: str
    path: MotionPath
    trace: JobTrace
    counts: Counts           # (K, 3n) demands relative to home
    t_end: float | None = None
    written: int = 0
    ticks: int = 0           # ticks streamed: the path's clock (one period each)
    sample: int = 0          # the sample demanded on the last tick
