"""The extensible runner's per-tick logic: which demand to send, given the encoders and the job.

:class:`Streamer` is the ``stack`` of :class:`hw_bridge.loop.LoopRunner` for the extensible arm
(loop thread only). Each tick it turns the encoders into racks, Delta and the measured tip,
then either streams the running job's next sample (one period of the path per tick: a late
tick delays the path, it never skips ahead), or (idle) holds the last
demand or follows the console's newest command within the rack, motor and tip speed limits and
the rack and bending limits. Without an armed device it only measures (state ``disarmed``) or
reports that nothing is connected. It publishes an immutable
:class:`~hw_bridge.extensible_jobs.RunnerSnapshot` every tick.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np

from core.kinematics import delta as dk
from core.planning.paths import MotionPath
from core.robots import ExtensibleArm
from hw_bridge.extensible_jobs import (ARM_FIRST, Array, Counts, Job, JobResult, JobTrace,
                                       PoseLink, RunnerSnapshot, concat_paths, home_counts, joint_move,
                                       measure, planned_motor_speed)


class Streamer:
    """The loop's ``stack``: decides each tick's demand (loop thread only)."""

    def __init__(self, robot: ExtensibleArm, period_s: float, link: PoseLink | None,
                 settle_counts: int, settle_timeout: float, margin: float = 0.98) -> None:
        self.robot, self.period, self.link = robot, period_s, link
        self.settle_counts, self.settle_timeout = settle_counts, settle_timeout
        self.v_rack, self.v_tip = robot.rack_speed * margin, robot.tip_speed * margin
        self.v_motor = planned_motor_speed(robot, 1.0 / period_s, margin)
        self.home = home_counts(robot)
        self.armed = False
        self.hold_L: Array | None = None
        self.track_L: Array | None = None
        self.seen_seq: int | None = None
        self.job: Job | None = None
        self.recent: Job | None = None  # the running or last job, for the snapshot
        self.fault: str | None = None
        self.message = "not connected"
        self.last_result: JobResult | None = None
        self.on_result: Callable[[JobResult], None] = lambda r: None
        self._held: list[JobResult] | None = None  # results of the tick being computed
        self.measured_L: Array | None = None
        self.snapshot = RunnerSnapshot("disconnected", message=self.message)

    def _counts(self, lengths: Array) -> Counts:
        return dk.motor_counts_from_lengths(self.robot, lengths) - self.home

    def _delta(self, lengths: Array) -> Array:
        return dk.delta_from_actuators(lengths, self.robot.phi, self.robot.L0)

    def _tip(self, lengths: Array) -> Array:
        return dk.tip_position(self.robot, self._delta(lengths))

    def _feasible(self, lengths: Array) -> Array:
        return dk.limit_rack_lengths(self.robot, lengths)

    # -- commands (loop thread) ------------------------------------------------------------
    def connected(self, encoders: Counts, follow: bool) -> None:
        """The device was just armed at ``encoders``: hold there (or follow the console)."""
        self.armed, self.fault = True, None
        self.measured_L = measure(self.robot, encoders, self.home)[0]
        self.hold_L = self._feasible(self.measured_L)
        self.track_L, self.message = None, "holding"
        self.seen_seq = -1 if follow else self._setpoint_seq()

    def disarmed(self, message: str, fault: str | None = None) -> None:
        """The device stopped being commanded (operator Disarm / Disconnect / Connect)."""
        if self.job is not None:
            self._end_job(False, f"aborted: {message}")
        self.armed, self.track_L = False, None
        self.fault, self.message = fault, message

    def _setpoint_seq(self) -> int | None:
        sp = self.link.setpoint() if self.link else None
        return None if sp is None else sp[0]

    def start_job(self, job_id: int, label: str, path: MotionPath) -> None:
        if not self.armed or self.measured_L is None:
            why = f"not started: {self.fault or ARM_FIRST}"
            self._finish(JobResult(job_id, label, False, why, None, None, None))
            return
        if self.job is not None:
            self._end_job(False, f"replaced by job {job_id}")
        start = self._feasible(self.measured_L)
        if np.abs(path.lengths[0] - start).max() > 5e-4:  # join it from where the motors are
            lead = joint_move(self.robot, start, path.lengths[0], rate_hz=path.rate_hz)
            path = concat_paths(lead, path)
        trace = JobTrace(path.times, path.targets, path.tips,
                         np.full((len(path.times), 3), np.nan))
        self.job = self.recent = Job(job_id, label, path, trace,
                                     path.motor_counts - self.home)
        self.track_L = None
        self.message = f"{label}: running"

    def halt(self, t: float) -> None:
        """Operator stop: hold where the motors are."""
        if self.measured_L is not None:
            self.hold_L = self._feasible(self.measured_L)
        self.track_L = None
        if self.job is not None:
            self._end_job(False, "stopped by operator; holding position")
        self.settle_link()

    def stop(self, t: float, reason: str = "stopped") -> None:
        """Called by the loop on a device read/write failure: stop commanding, report the fault."""
        self.armed = False
        self.fault = reason.removeprefix("device: ")
        if self.job is not None:
            self._end_job(False, f"aborted: {self.fault}")
        self.message = f"fault: {self.fault}"

    def device_fault(self, t: float, reason: str) -> None:
        """The loop's device read/write failed: :meth:`stop`; the next update publishes it."""
        self.stop(t, reason)

    def _end_job(self, ok: bool, message: str) -> None:
        job = self.job
        assert job is not None
        self.job = None
        tip = target = err = None
        if self.measured_L is not None:
            tip = self._tip(self.measured_L)
            target = job.path.targets[-1]
            err = float(np.linalg.norm(tip - target))
        self.message = f"{job.label}: {message}"
        self._finish(JobResult(job.job_id, job.label, ok, message, tip, target, err))

    def _finish(self, result: JobResult) -> None:
        self.last_result = result
        if self._held is not None:  # inside update: told once its snapshot is published
            self._held.append(result)
        else:
            self.on_result(result)

    def settle_link(self) -> None:
        if self.link is not None and self.hold_L is not None:
            self.seen_seq = self.link.settled(self._delta(self.hold_L))

    # -- one tick --------------------------------------------------------------------------
    def update(self, encoders: Counts, t: float,
               periods: int = 1) -> tuple[Counts | None, RunnerSnapshot]:
        """One tick: the demand to write (None: write nothing) and the snapshot it published.

        A job that ends in this tick is reported (``on_result``) only after the snapshot that
        shows it ended (``holding``, its ``last_result``) is published, so whoever is woken by
        the result reads telemetry that agrees with it.
        """
        self._held = []
        try:
            return self._update(encoders, t, periods)
        finally:
            held, self._held = self._held, None
            for result in held:
                self.on_result(result)

    def _update(self, encoders: Counts, t: float,
                periods: int) -> tuple[Counts | None, RunnerSnapshot]:
        if encoders.size == 0:  # no link (never connected, disconnected, or after a fault)
            self.armed, self.measured_L = False, None
            state = "fault" if self.fault else "disconnected"
            self.snapshot = dataclasses.replace(self.snapshot, state=state, fault=self.fault,
                                                message=self.message, last_result=self.last_result)
            return None, self.snapshot
        L, delta, tip = measure(self.robot, encoders, self.home)
        self.measured_L = L
        job = self.job
        if not self.armed:  # configured but not armed: telemetry only, nothing is written
            demand, state = None, ("fault" if self.fault else "disarmed")
        elif job is None:
            demand, state = self._idle(periods)
        else:
            demand, state = self._stream(job, encoders, tip, t)
        if self.link is not None and (job is not None or self.link.always_report):
            self.link.measured(delta)
        j, tick = self.recent, self.snapshot.tick + 1
        if j is None:
            self.snapshot = RunnerSnapshot(state, tick, measured_delta=delta, measured_tip=tip,
                                           fault=self.fault, message=self.message,
                                           last_result=self.last_result)
        else:
            k = len(j.path.times)
            self.snapshot = RunnerSnapshot(
                state, tick, j.job_id, j.label, min(j.sample, k - 1), k,
                delta, tip, self.fault, self.message, j.trace, j.written, self.last_result)
        return demand, self.snapshot

    def _idle(self, periods: int) -> tuple[Counts, str]:
        assert self.hold_L is not None
        sp = self.link.setpoint() if self.link else None
        if sp is not None and sp[0] != self.seen_seq:
            self.seen_seq = sp[0]
            self.track_L = self._feasible(dk.robot_rack_lengths(self.robot, sp[1]))
        if self.track_L is None:
            return self._counts(self.hold_L), "holding"
        step = self.track_L - self.hold_L
        rack = float(np.abs(step).max())
        motor = float(np.abs(dk.motors_from_lengths(step)).max())
        if max(rack, motor) < 1e-7:
            self.hold_L, self.track_L = self.track_L, None
            return self._counts(self.hold_L), "holding"
        dt = self.period * periods
        s = min(1.0, self.v_rack * dt / max(rack, 1e-300), self.v_motor * dt / max(motor, 1e-300))
        nxt = self.hold_L + s * step  # on the segment between feasible racks: feasible
        moved = float(np.linalg.norm(self._tip(nxt) - self._tip(self.hold_L)))
        if moved > self.v_tip * dt:
            nxt = self.hold_L + s * (self.v_tip * dt / moved) * step
        self.hold_L = nxt
        return self._counts(nxt), "following"

    def _stream(self, job: Job, enc: Counts, tip: Array, t: float) -> tuple[Counts, str]:
        k_last = len(job.path.times) - 1
        # The path's clock advances one period per tick, whatever the wall clock did: after a
        # late tick (a stalled host) the device gets the next sample, not the one due by now,
        # which it could only chase straight across a corner faster than planned.
        k = min(int(job.ticks * self.period * job.path.rate_hz + 1e-9), k_last)
        job.ticks, job.sample = job.ticks + 1, k
        while job.written <= k:  # (a path sampled faster than the loop: skipped samples)
            job.trace.measured[job.written] = tip
            job.written += 1
        demand = job.counts[k]
        if k < k_last:
            return demand, "running"
        job.t_end = t if job.t_end is None else job.t_end
        off = int(np.abs(enc - demand).max())
        if off <= self.settle_counts or t - job.t_end >= self.settle_timeout:
            self.hold_L = job.path.lengths[-1]
            ok = off <= self.settle_counts
            self._end_job(ok, "done" if ok else f"did not settle ({off} counts off)")
            self.settle_link()
            return demand, "holding"
        return demand, "settling"
