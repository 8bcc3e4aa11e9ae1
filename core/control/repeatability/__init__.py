"""Open versus closed loop repeatability of the extensible arm on the slipping-rack model.

Table I of Hughes 2020 measures "reliability in positioning" by moving to a point from the
retracted position five times, for three points: +-19 mm with one segment, +-29 mm with two, open
loop on the motor encoders. :func:`study` repeats that protocol on
:class:`core.control.rack_slip.SlippingRacks` (the emulator's slip model, without the serial
link: a move ends with the motors at their demand) for three ways of positioning:

* ``open``: the tip IK's racks (eq. 4-6), as in the paper;
* ``encoders``: closed loop (:func:`core.control.closed_loop.position`) on the posture the
  encoders give, which cannot see slip and so changes nothing;
* ``tip``: closed loop on the measured tip (noise ``SlipModel.tip_noise``, ``samples`` readings
  averaged per correction), which corrects the slip.

``python -m core.control.repeatability [--segments 1 2] [--points 3] [--repeats 5] [--seed S]
[--slip F] [--jitter J] [--tip-noise M] [--json]`` prints the table (mm) with Table I's figures.
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import numpy as np
import numpy.typing as npt

from core.control.closed_loop import ClosedLoopSettings, position
from core.control.rack_slip import SlipModel, SlippingRacks
from core.kinematics import delta as dk
from core.robots import ExtensibleArm

Array = npt.NDArray[np.float64]
Mode = Literal["open", "encoders", "tip"]
MODES: tuple[Mode, ...] = ("open", "encoders", "tip")
TABLE_I_MM = {1: 19.0, 2: 29.0}
"""Hughes 2020, Table I, "reliability in positioning" (+- mm) on the hardware, open loop."""


def with_segments(robot: ExtensibleArm, n: int) -> ExtensibleArm:
    """The same arm with ``n`` segments (Table I reports one and two)."""
    return dataclasses.replace(robot, n_segments=n, n_motors=3 * n)


def sample_targets(robot: ExtensibleArm, count: int, seed: int, *, bend: tuple[float, float] =
                   (0.15, 0.6), rack_margin: tuple[float, float] = (0.03, 0.06)) -> Array:
    """``count`` reachable tip targets (count, 3), reproducible from ``seed``.

    Every segment is bent by a fraction ``bend`` of theta_max toward a uniform direction and
    extended so that its racks stay ``rack_margin`` (m) inside [rack_min, rack_max]: the targets
    leave the closed loop room to lengthen racks that slipped short.
    """
    rng = np.random.default_rng(seed)
    n = robot.n_segments
    out = np.empty((count, 3))
    for k in range(count):
        theta = rng.uniform(*bend, n) * robot.theta_max
        az = rng.uniform(-np.pi, np.pi, n)
        b = robot.d * theta
        lo = robot.rack_min + rack_margin[0] + b - robot.L0
        hi = robot.rack_max - rack_margin[1] - b - robot.L0
        delta = np.stack([b * np.cos(az), b * np.sin(az), rng.uniform(lo, hi)], axis=-1)
        out[k] = dk.tip_position(robot, delta)
    return out


class SimulatedArm:
    """Slipping racks driven through encoder counts, as the runner drives the emulator."""

    def __init__(self, robot: ExtensibleArm, model: SlipModel, samples: int = 10) -> None:
        self.robot = robot
        self.racks = SlippingRacks(robot, model)
        self.samples = samples
        self.home = dk.motor_counts_from_lengths(
            robot, dk.robot_rack_lengths(robot, np.zeros((robot.n_segments, 3))))

    def move(self, lengths: Array) -> None:
        """Motors to the counts of rack lengths (n, 3); the racks slip."""
        counts = dk.motor_counts_from_lengths(self.robot, lengths) - self.home
        self.racks.move(counts.reshape(self.robot.n_segments, 3) / self.robot.counts_per_metre)

    def retract(self) -> None:
        self.move(dk.robot_rack_lengths(self.robot, np.zeros((self.robot.n_segments, 3))))

    def tip_measured(self) -> Array:
        """Tip measurement (noisy, averaged over ``samples`` readings)."""
        return self.racks.measured_tip(self.samples)

    def tip_from_encoders(self) -> Array:
        """h of the posture the encoders give (blind to slip)."""
        r = self.robot
        counts = np.rint(self.racks.encoder_m.reshape(-1) * r.counts_per_metre) + self.home
        lengths = dk.lengths_from_motor_counts(r, counts)
        return dk.tip_position(r, dk.delta_from_actuators(lengths, r.phi, r.L0))


def reach(arm: SimulatedArm, target: Array, mode: Mode,
          settings: ClosedLoopSettings = ClosedLoopSettings()) -> Array:
    """Retract, position the tip at ``target`` by ``mode``; returns the true tip reached."""
    arm.retract()
    if mode == "open":
        settings = dataclasses.replace(settings, iterations=0)
    measure = arm.tip_measured if mode == "tip" else arm.tip_from_encoders
    position(arm.robot, target, arm.move, measure, settings=settings)
    return arm.racks.tip.copy()


@dataclasses.dataclass(frozen=True)
class Spread:
    """Tips reached (points, repeats, 3) for targets (points, 3), in metres."""

    targets: Array
    tips: Array

    @property
    def errors(self) -> Array:
        """Distance of every reached tip to its target (points, repeats)."""
        return np.linalg.norm(self.tips - self.targets[:, None, :], axis=-1)

    @property
    def spread(self) -> Array:
        """Per point and axis +-(max - min) / 2 (points, 3): Table I's "+-"."""
        return 0.5 * np.ptp(self.tips, axis=1)

    def summary(self) -> dict[str, float]:
        """Mean and max tip error, mean and max per-axis spread (m)."""
        return {"mean_error": float(self.errors.mean()), "max_error": float(self.errors.max()),
                "mean_spread": float(self.spread.mean()), "max_spread": float(self.spread.max())}


def study(robot: ExtensibleArm, model: SlipModel, mode: Mode, *, points: int = 3,
          repeats: int = 5, seed: int = 0, samples: int = 10) -> Spread:
    """Table I's protocol: ``repeats`` moves from the retracted pose to each of ``points``
    seeded targets, positioned by ``mode`` on slipping racks (slip and noise seeded by ``model``)."""
    targets = sample_targets(robot, points, seed)
    arm = SimulatedArm(robot, model, samples)
    tips = np.array([[reach(arm, t, mode) for _ in range(repeats)] for t in targets])
    return Spread(targets, tips)
