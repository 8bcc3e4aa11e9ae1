"""trajGen (§4.2): jerk-limited, phase-synchronised curvature trajectories from ruckig, online.

:class:`TrajectoryGenerator` keeps ruckig's input/output parameter objects and is advanced by
one :meth:`TrajectoryGenerator.update` per control period. A new target may be set at any time;
ruckig then replans from the current reference state (position, velocity, acceleration), so the
reference stays continuous in acceleration. Rest-to-rest motions are time-optimal under the
per-DOF velocity / acceleration / jerk limits, all segments arrive together (phase
synchronisation, ruckig falls back to time synchronisation when phase is impossible) and the
reference never passes the target (no overshoot).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import numpy.typing as npt
from ruckig import InputParameter, OutputParameter, Result, Ruckig, Synchronization

from core.control.params import TrajectoryParams
from core.robots import SoftArm

Array = npt.NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class TrajectorySample:
    """Reference at the current period; ``finished`` once it rests at the target."""

    position: Array
    velocity: Array
    acceleration: Array
    finished: bool
    duration: float
    elapsed: float


class TrajectoryGenerator:
    """Online ruckig wrapper over N curvature DOFs.

    Args:
        params: Per-DOF limits and synchronisation (``TrajectoryParams.from_robot``).
        dt: Control period, s.
        kappa_max: Targets must satisfy ``|kappa| <= kappa_max`` (bad targets raise).
    """

    def __init__(self, params: TrajectoryParams, dt: float, kappa_max: float):
        if not dt > 0:
            raise ValueError(f"dt must be > 0, got {dt}")
        self.n = len(params.max_velocity)
        self.dt = dt
        self.kappa_max = float(kappa_max)
        self.otg = Ruckig(self.n, dt)
        self.inp = InputParameter(self.n)
        self.out = OutputParameter(self.n)
        self.inp.max_velocity = params.max_velocity.tolist()
        self.inp.max_acceleration = params.max_acceleration.tolist()
        self.inp.max_jerk = params.max_jerk.tolist()
        self.inp.synchronization = (Synchronization.Phase if params.synchronization == "phase"
                                    else Synchronization.Time)
        self.error: str | None = None
        self.reset(np.zeros(self.n))

    @classmethod
    def from_robot(cls, robot: SoftArm, dt: float) -> "TrajectoryGenerator":
        """Generator with the robot file's ``[trajectory]`` limits."""
        return cls(TrajectoryParams.from_robot(robot), dt, robot.kappa_max)

    def _vec(self, name: str, value: npt.ArrayLike) -> Array:
        v = np.asarray(value, dtype=float)
        if v.shape != (self.n,) or not np.all(np.isfinite(v)):
            raise ValueError(f"{name} must be {self.n} finite values, got shape {v.shape}")
        return v

    def reset(self, position: npt.ArrayLike, velocity: npt.ArrayLike | None = None,
              acceleration: npt.ArrayLike | None = None) -> None:
        """Restart from a state (e.g. the measured curvature at rest) and hold it as the target.

        A position beyond the curvature limit (a measured arm bent past it) is taken as it is,
        but the target held is the position clamped to +-kappa_max: a target never lies beyond
        the limit, so holding or resuming from such a state moves the reference back within it.
        """
        pos = self._vec("position", position)
        vel = np.zeros(self.n) if velocity is None else self._vec("velocity", velocity)
        acc = np.zeros(self.n) if acceleration is None else self._vec("acceleration", acceleration)
        self.otg.reset()
        self.inp.current_position = pos.tolist()
        self.inp.current_velocity = vel.tolist()
        self.inp.current_acceleration = acc.tolist()
        self.inp.target_position = np.clip(pos, -self.kappa_max, self.kappa_max).tolist()
        self.inp.target_velocity = [0.0] * self.n
        self.inp.target_acceleration = [0.0] * self.n
        at_rest = not np.any(vel) and not np.any(acc) and np.all(np.abs(pos) <= self.kappa_max)
        self._sample = TrajectorySample(pos, vel, acc, bool(at_rest), 0.0, 0.0)
        self.error = None

    @property
    def target(self) -> Array:
        """Current target curvatures, (N,)."""
        return np.array(self.inp.target_position)

    @property
    def sample(self) -> TrajectorySample:
        """The latest reference (after the last update or reset)."""
        return self._sample

    def set_target(self, kappa: npt.ArrayLike) -> None:
        """New rest target; takes effect at the next :meth:`update` (bad input changes nothing)."""
        k = self._vec("target", kappa)
        if np.any(np.abs(k) > self.kappa_max + 1e-9):
            raise ValueError(f"target curvature beyond +-{self.kappa_max:g} 1/m: {np.round(k, 3).tolist()}")
        self.inp.target_position = k.tolist()

    def hold(self) -> None:
        """Stop the reference where it is now (velocity and acceleration zeroed), e.g. on STOP."""
        self.reset(self._sample.position)

    def update(self, periods: int = 1) -> TrajectorySample:
        """Advance the reference by ``periods`` control periods (> 1 after skipped ticks)."""
        if periods < 1:
            raise ValueError(f"periods must be >= 1, got {periods}")
        result = Result.Finished
        for _ in range(periods):
            result = self.otg.update(self.inp, self.out)
            if result not in (Result.Working, Result.Finished):
                self.error = f"ruckig: {result.name}"
                self.hold()
                return self._sample
            self.out.pass_to_input(self.inp)
        self._sample = TrajectorySample(
            np.array(self.out.new_position), np.array(self.out.new_velocity),
            np.array(self.out.new_acceleration), result == Result.Finished,
            float(self.out.trajectory.duration), float(self.out.time))
        return self._sample
