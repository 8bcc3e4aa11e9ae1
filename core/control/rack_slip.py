"""Rack slip under load, so an open-loop move of the extensible arm misses as on hardware.

Hughes 2020 drives the racks open loop from the motors' encoders and measures +-19 mm (one
segment) and +-29 mm (two segments) of repeatability (Table I). The encoders count the motor
shafts: a rack that slips relative to its pinion (teeth skipping, the printed rack flexing out of
mesh under the arm's weight) moves the arm without moving an encoder. This module models that
slip, so the emulator and the closed-loop studies have something to correct.

Model (per move, in motor travel m = U^-1 L, metres of rack driven by one pinion):

* When motor k starts a move (it was at rest for at least ``rest_s``, or it reverses: the
  pinion's teeth take up the other flank, and the runner queues the next move as soon as one
  settles, so between a retract and the move out a motor may rest for less than ``rest_s``), a
  slip fraction is drawn for that move: ``s_k = fraction * load_i + jitter * N(0, 1)``, clipped to [0, 0.5], where
  ``load_i = (n - i) / n`` for a motor on platform i (0-based): the proximal platform carries
  every segment beyond it, the last one only its own.
* While it moves, the rack follows the pinion by ``(1 - s_k)`` of the encoder's travel:
  ``dm_actual = (1 - s_k) dm_encoder``. So one move from rest ends at
  ``m_actual = m_start + (1 - s_k) (m_encoder_end - m_encoder_start)`` (closed form).
* At the retracted pose (every encoder at 0 and at rest) the racks sit on their hard stops: the
  accumulated slip is cleared (re-homed), so every move from the retracted pose starts clean,
  as in Table I's protocol.

What measures what. The encoders read ``m_encoder`` exactly; the arm's true rack lengths are
``U (m_home + m_actual)`` (:func:`core.kinematics.delta.lengths_from_motors`). A tip
measurement (motion capture or an IMU-based posture estimate; here the true tip plus Gaussian
noise of ``tip_noise`` per axis) is the only channel that sees the slip: a loop closed on the
encoders alone cannot correct it (see :mod:`core.control.closed_loop`).

The bend of a segment is not in the model (the load factor is per platform only), and slip is
symmetric in direction; both are documented choices, not measured on the hardware.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import numpy.typing as npt

from core.kinematics import delta as dk
from core.robots import ExtensibleArm

Array = npt.NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class SlipModel:
    """Slip parameters (dimensionless fractions of a move's travel, metres for noise).

    The defaults put the open-loop spread of :mod:`core.control.repeatability`'s seeded study
    near Table I's (+-19 mm one segment, +-29 mm two): chosen, not identified on hardware.

    Attributes:
        fraction: Mean fraction of its travel that the most loaded (proximal) rack loses.
        jitter: Standard deviation of the per-move random part of the fraction.
        tip_noise: Standard deviation (m) of the tip measurement per axis.
        rest_s: A motor still for at least this long starts a new move (new draw); so does a
            motor that reverses.
        seed: Seed of the slip draws and the measurement noise.
    """

    fraction: float = 0.05
    jitter: float = 0.015
    tip_noise: float = 0.002
    rest_s: float = 0.2
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("fraction", "jitter", "tip_noise", "rest_s"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"slip {name} must be finite and >= 0, got {v!r}")
        if self.fraction > 0.5:
            raise ValueError(f"slip fraction must be <= 0.5, got {self.fraction!r}")

    def load_fractions(self, n_segments: int) -> Array:
        """Mean slip fraction of every motor, (n, 3): ``fraction * (n - i) / n`` on platform i."""
        load = (n_segments - np.arange(n_segments)) / n_segments
        return np.repeat(self.fraction * load[:, None], 3, axis=1)


class SlippingRacks:
    """The racks' true travel behind the encoders (stateful; one per emulated arm).

    Args:
        robot: The extensible arm.
        model: Slip parameters.
    """

    def __init__(self, robot: ExtensibleArm, model: SlipModel) -> None:
        self.robot = robot
        self.model = model
        n = robot.n_segments
        self.rng = np.random.default_rng(model.seed)
        self.home_m = dk.motors_from_lengths(dk.robot_rack_lengths(robot, np.zeros((n, 3))))
        self.mean = model.load_fractions(n)
        self.encoder_m = np.zeros((n, 3))  # motor travel from the retracted pose, read by encoders
        self.actual_m = np.zeros((n, 3))   # the racks' true travel
        self.slip = self.mean.copy()       # the fraction of the current (or last) move
        self.rest = np.full((n, 3), np.inf)  # how long each motor has been still (s)
        self.direction = np.zeros((n, 3))  # sign of each motor's last motion (0: none yet)

    def step(self, encoder_m: npt.ArrayLike, dt: float) -> None:
        """The motors moved to ``encoder_m`` (n, 3) (m from the retracted pose) in ``dt`` s."""
        new = np.asarray(encoder_m, dtype=float).reshape(self.encoder_m.shape)
        d = new - self.encoder_m
        moving = d != 0.0
        start = moving & ((self.rest >= self.model.rest_s) | (np.sign(d) != self.direction))
        if start.any():
            draw = self.mean[start] + self.model.jitter * self.rng.standard_normal(int(start.sum()))
            self.slip[start] = np.clip(draw, 0.0, 0.5)
        self.actual_m += (1.0 - self.slip) * d
        self.rest = np.where(moving, 0.0, self.rest + dt)
        self.direction = np.where(moving, np.sign(d), self.direction)
        self.encoder_m = new
        if not new.any() and not moving.any():
            self.actual_m[:] = 0.0  # retracted onto the hard stops: re-homed

    def step_counts(self, encoder_counts: npt.ArrayLike, dt: float) -> None:
        """:meth:`step` with encoder counts (3n,) (the emulator's motor positions)."""
        c = np.asarray(encoder_counts, dtype=float)
        self.step(c.reshape(self.robot.n_segments, 3) / self.robot.counts_per_metre, dt)

    def move(self, encoder_m: npt.ArrayLike) -> None:
        """One whole move from rest (a new slip draw for every motor that moves)."""
        self.rest[:] = np.inf
        self.step(encoder_m, self.model.rest_s)
        self.step(encoder_m, self.model.rest_s)  # and at rest again

    @property
    def lengths(self) -> Array:
        """True rack lengths (n, 3)."""
        return dk.lengths_from_motors(self.home_m + self.actual_m)

    @property
    def tip(self) -> Array:
        """True tip (3,)."""
        lengths = self.lengths
        return dk.tip_position(self.robot, dk.delta_from_actuators(lengths, self.robot.phi,
                                                                   self.robot.L0))

    def measured_tip(self, samples: int = 1) -> Array:
        """Tip measurement: the true tip plus noise, averaged over ``samples`` readings."""
        noise = self.rng.standard_normal((max(1, samples), 3)).mean(axis=0)
        return self.tip + self.model.tip_noise * noise
