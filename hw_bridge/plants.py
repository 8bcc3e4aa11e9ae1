"""Simple device-side plants for the emulator: speed-limited motors and a soft-arm curvature lag.

These are deliberately small stand-ins for real hardware so the serial stack can be exercised
end to end. The device emulator's soft arm now runs the richer
:class:`core.control.sim.EmulatorPlant`; :class:`CurvaturePlant` stays as the minimal
closed-form lag (``step(cylinder_counts, dt)``, ``kappa``, ``shape()``) for unit tests of the
mocap path.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]


class MotorBank:
    """Motors with quadrature encoders tracking position demands under a speed limit.

    Each motor moves straight toward its target at up to ``max_speed`` counts/s (a position
    loop with a saturated, overshoot-free response); the encoder reads the rounded position.
    """

    def __init__(self, n: int, max_speed: float):
        if n < 1:
            raise ValueError(f"MotorBank needs at least one motor, got {n}")
        if not max_speed > 0:
            raise ValueError(f"max_speed must be > 0 counts/s, got {max_speed}")
        self.n = n
        self.max_speed = float(max_speed)
        self.position = np.zeros(n)
        self.target = np.zeros(n)
        self.velocity = np.zeros(n)
        self.enabled = False

    @property
    def encoders(self) -> npt.NDArray[np.int64]:
        """Encoder counts, shape (n,)."""
        return np.rint(self.position).astype(np.int64)

    def set_targets(self, mask: int, counts: tuple[int, ...]) -> None:
        """Set targets of the motors whose bits are set in ``mask`` (in bit order)."""
        idx = [i for i in range(self.n) if mask >> i & 1]
        if len(idx) != len(counts):
            raise ValueError(f"mask selects {len(idx)} of {self.n} motors, got {len(counts)} counts")
        self.target[idx] = counts

    def hold(self) -> None:
        """Target the current position (stop where we are)."""
        self.target = self.position.copy()
        self.velocity[:] = 0.0

    def step(self, dt: float) -> None:
        """Advance by ``dt`` seconds; disabled motors do not move."""
        if not self.enabled or dt <= 0:
            self.velocity[:] = 0.0
            return
        err = self.target - self.position
        move = np.clip(err, -self.max_speed * dt, self.max_speed * dt)
        self.position += move
        self.velocity = move / dt


class CurvaturePlant:
    """Soft-arm segments whose curvature lags the drive-cylinder volumes (first order).

    Segment ``i`` is driven by cylinders ``2i`` (left, counter-clockwise) and ``2i+1``; its
    steady-state curvature is ``(c[2i] - c[2i+1]) / counts_per_kappa`` clipped to
    ``+-kappa_max``, reached with time constant ``tau``:
    ``d kappa / dt = (kappa_ss - kappa) / tau`` (integrated exactly over each step).
    Channel ``2N`` (the gripper) does not affect the shape.

    Args:
        n_segments: N.
        counts_per_kappa: Cylinder count difference per 1/m of curvature.
        tau: Time constant, s.
        kappa_max: Curvature saturation, 1/m.
        forward_kinematics: ``fk(kappa) -> (N+1, 3)`` segment-end poses (e.g. a partial of
            ``core.kinematics.planar.forward_kinematics``), used by :meth:`shape`.
    """

    def __init__(self, n_segments: int, counts_per_kappa: float, tau: float, kappa_max: float,
                 forward_kinematics: Callable[[Array], Array]):
        self.n = n_segments
        self.counts_per_kappa = float(counts_per_kappa)
        self.tau = float(tau)
        self.kappa_max = float(kappa_max)
        self._fk = forward_kinematics
        self.kappa = np.zeros(n_segments)

    def steady_state(self, cylinders: npt.ArrayLike) -> Array:
        """Curvatures the given cylinder counts settle to, shape (N,)."""
        c = np.asarray(cylinders, dtype=float)
        if c.shape[-1] < 2 * self.n:
            raise ValueError(f"need {2 * self.n} cylinder channels, got {c.shape[-1]}")
        diff = c[0:2 * self.n:2] - c[1:2 * self.n:2]
        return np.clip(diff / self.counts_per_kappa, -self.kappa_max, self.kappa_max)

    def step(self, cylinders: npt.ArrayLike, dt: float) -> None:
        """Advance the lag by ``dt`` seconds toward the steady state of ``cylinders``."""
        target = self.steady_state(cylinders)
        self.kappa = target + (self.kappa - target) * np.exp(-dt / self.tau)

    def shape(self) -> Array:
        """Segment-end poses [x, y, theta], shape (N+1, 3)."""
        return np.asarray(self._fk(self.kappa), dtype=float)
