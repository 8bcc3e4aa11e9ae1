"""Closed-loop tip positioning of the extensible arm: eq. (5) driven by the measured posture.

Hughes 2020 (end of section II-C) sends its commands open loop and suggests closing the loop
"by substituting the actual posture of the robot to all the Delta appearing in the right side
of" eq. (5), which adds a nonlinear integral action. :func:`correction` is one Euler step of
that system, with unit gain, in rack space (where the limits are a box, as in
:mod:`core.kinematics.delta_ik`):

    L_cmd <- limit(L_cmd + (J P)^T (J P (J P)^T + lambda^2 I)^-1 (x_ref - x_meas)),

J = dh/dL at the measured posture, P the null space of the active limits (a rack at a limit the
step would push further out is held), ``limit`` the rack box and bending limits
(:func:`core.kinematics.delta.limit_rack_lengths`, eq. (4)'s constraint set). The command
accumulates the corrections (the integral action), so a constant slip or offset is driven out.
A segment at its bending limit is only projected back onto it (not held as a set-based task):
a target whose corrected command would need more bend than theta_max keeps the error that the
limit leaves (measured: targets bent to theta_max with 5-10 % slip stay 20-30 mm off), which is
why :func:`core.control.repeatability.sample_targets` keeps its targets inside the limits.

Which measurement corrects what:

* ``x_meas`` from the encoders (h of the encoder posture): corrects only what the encoders see,
  i.e. motors that did not reach their demand. A rack slipping on its pinion moves no encoder,
  so this loop leaves the slip error untouched.
* ``x_meas`` from a tip measurement (motion capture, or a posture from IMUs on the segments put
  through h): corrects slip and load deflection, down to the measurement's noise.

Once per settled move, not continuously during it: the tip sensor is read in the console
process, while the runner streams a planned joint move from its own real-time process, so a
correction during the move needs the tip stream inside the runner's 100 Hz loop (a new streamer
mode) or a new job from the console several times a second (each one replanned from where the
motors are). It would save time, not accuracy: both end within the sensor's noise, and a
correction made during the move slips like the rest of that move. Measured on the emulator with
20 % slip (the Repeatability panel, 2 moves per loop to (-50, 152, 323) mm, 30 tip frames per
measurement, a loaded machine): 4.5 corrections per move, each a short move, a settle and a
measurement; a repetition (retract, move, measure) took 7.0 s open loop and 11.1 s closed loop,
for a mean error of 0.8 mm instead of 39 mm and a +- spread of 0.4 mm instead of 14.9 mm.

:func:`position` runs moves and corrections against any plant given as two callables (move the
racks to commanded lengths; measure the tip), so the same loop runs against
:class:`core.control.rack_slip.SlippingRacks` in tests and benchmarks and against the runner and
the emulator's tip stream in :mod:`hw_bridge.extensible_closed_loop`.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np
import numpy.typing as npt

from core.kinematics import delta as dk
from core.kinematics.delta_ik import solve_tip_ik
from core.robots import ExtensibleArm

Array = npt.NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class ClosedLoopSettings:
    """Correction settings.

    Attributes:
        iterations: Correction moves at most after the first (open-loop) move.
        tolerance: Stop once the measured tip is this close to the target (m).
        gain: Fraction of the eq. (5) step taken per correction (1: full Gauss-Newton step).
        damping: lambda of the damped pseudo-inverse (m).
    """

    iterations: int = 6
    tolerance: float = 0.001
    gain: float = 1.0
    damping: float = 1e-3

    def __post_init__(self) -> None:
        if self.iterations < 0:
            raise ValueError(f"iterations must be >= 0, got {self.iterations}")
        if not (self.tolerance > 0 and 0 < self.gain <= 1 and self.damping >= 0):
            raise ValueError("tolerance must be > 0, gain in (0, 1] and damping >= 0")


@dataclasses.dataclass(frozen=True)
class ClosedLoopResult:
    """Outcome of :func:`position`.

    Attributes:
        lengths: Final commanded rack lengths (n, 3).
        measured: Measured tip after every move (k + 1, 3), the open-loop move first.
        corrections: Correction moves made.
    """

    lengths: Array
    measured: Array
    corrections: int


def _tip_jacobian_in_lengths(robot: ExtensibleArm, lengths: Array) -> Array:
    """dh/dL (3, 3n) at rack lengths (n, 3)."""
    delta = dk.delta_from_actuators(lengths, robot.phi, robot.L0)
    _, J_delta = dk.chain_tip_and_jacobian(delta, robot.L0, robot.d)
    M = dk.rack_matrix(robot.phi)
    n = robot.n_segments
    return (J_delta.reshape(3, n, 3) @ M).reshape(3, 3 * n)


def correction(robot: ExtensibleArm, target: npt.ArrayLike, commanded: npt.ArrayLike,
               measured_tip: npt.ArrayLike, posture: npt.ArrayLike, *, gain: float = 1.0,
               damping: float = 1e-3) -> Array:
    """One step of eq. (5) with the measured posture: new commanded rack lengths (n, 3).

    Args:
        robot: The extensible arm.
        target: x_ref (3,), m.
        commanded: The rack lengths commanded now (n, 3) (the integrator's state).
        measured_tip: x_meas (3,): the tip measured (or h of the measured posture).
        posture: Rack lengths (n, 3) at which J is evaluated (the measured posture; the
            encoders' when nothing better is known).
        gain: Step fraction in (0, 1].
        damping: lambda of the damped pseudo-inverse.

    Returns:
        The corrected command, within the rack and bending limits.
    """
    n = robot.n_segments
    L = np.asarray(commanded, dtype=float).reshape(n, 3)
    e = np.asarray(target, dtype=float) - np.asarray(measured_tip, dtype=float)
    if e.shape != (3,) or not np.all(np.isfinite(e)) or not np.all(np.isfinite(L)):
        raise ValueError("target and measured_tip must be 3 finite numbers, commanded finite")
    J = _tip_jacobian_in_lengths(robot, np.asarray(posture, dtype=float).reshape(n, 3))
    flat = L.reshape(-1)
    free = np.ones(3 * n, dtype=bool)
    for _ in range(2):  # set-based rack limits: hold racks the step pushes out of the box
        Jf = np.where(free[None, :], J, 0.0)
        step = Jf.T @ np.linalg.solve(Jf @ Jf.T + damping**2 * np.eye(3), e)
        out = ((flat <= robot.rack_min) & (step < 0)) | ((flat >= robot.rack_max) & (step > 0))
        if not (out & free).any():
            break
        free &= ~out
    new = flat + gain * step
    return dk.limit_rack_lengths(robot, new.reshape(n, 3))


def position(robot: ExtensibleArm, target: npt.ArrayLike, move: Callable[[Array], None],
             measure_tip: Callable[[], Array], *, posture: Callable[[Array], Array] | None = None,
             settings: ClosedLoopSettings = ClosedLoopSettings()) -> ClosedLoopResult:
    """Move to the IK solution for ``target`` (open loop), then correct on the measured tip.

    Args:
        robot: The extensible arm.
        target: (3,) tip target, m.
        move: Moves the racks to commanded lengths (n, 3) and returns once settled.
        measure_tip: The tip measured now (3,).
        posture: Commanded lengths -> posture at which J is evaluated (default: the command).
        settings: Iterations, tolerance, gain, damping; ``iterations=0`` is the open loop.

    Raises:
        ValueError: the target is out of reach (nothing moves).
    """
    x = np.asarray(target, dtype=float)
    ik = solve_tip_ik(robot, x)
    if not ik.reachable:
        raise ValueError(f"target is out of reach by {ik.error * 1e3:.1f} mm")
    cmd = ik.lengths
    move(cmd)
    tips = [np.asarray(measure_tip(), dtype=float)]
    k = 0
    while k < settings.iterations and np.linalg.norm(x - tips[-1]) > settings.tolerance:
        at = cmd if posture is None else posture(cmd)
        new = correction(robot, x, cmd, tips[-1], at, gain=settings.gain,
                         damping=settings.damping)
        if np.allclose(new, cmd, atol=0.5 / robot.counts_per_metre, rtol=0):
            break  # nothing left the motors can do (below one count, or held at limits)
        cmd = new
        move(cmd)
        tips.append(np.asarray(measure_tip(), dtype=float))
        k += 1
    return ClosedLoopResult(lengths=cmd, measured=np.array(tips), corrections=k)
