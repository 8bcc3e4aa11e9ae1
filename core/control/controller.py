"""Cascaded closed-loop curvature controller: kappa_target -> 2N + 1 drive-cylinder demands (§4.1).

Per segment ``i`` the **outer loop** turns the curvature error into a differential cylinder
volume ``u_i`` (counts, left minus right)::

    u = c_k * (kappa_ref + T_v * kappa_dot_ref)      feed-forward: inverse plant gain + lag lead
        + kp * e + I - kd * d(kappa_meas)/dt          PI(D), derivative on the filtered measurement
    dI/dt = ki * e                                     while no limit is active
    anti-windup when a range or slew limit cut u: no integration of an error pushing further
    into the limit (conditional integration) and back-calculation k_aw (u_applied - u) bleeding
    I toward zero (never past it, so a feed-forward-only saturation cannot wind I backwards)

``u`` is split onto the antagonistic pair: ``left = b + max(u, 0)``, ``right = b + max(-u, 0)``,
where the base volume ``b`` is the **pre-pressurisation** of both channels of the root
segments (``actuation.prepressurised_segments``; the paper does this to stiffen them and shorten
their time constant) and ``cylinder_min`` elsewhere. The **inner loop** is the drive
cylinders' position servo (on the device, or the pistons of :class:`core.control.sim.SoftArmSim`);
the demands are clipped to the cylinder range and slewed at the piston speed here, so every
limit the inner loop would hit is known to the anti-windup. Channel ``2i`` is the left
(counter-clockwise) cylinder of segment ``i``, ``2i+1`` the right one, channel ``2N`` the gripper.

Pure: no threads, no I/O, one :meth:`CurvatureController.step` per control period.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import numpy.typing as npt

from core.control.params import ControllerParams
from core.robots import SoftArm

Array = npt.NDArray[np.float64]


def _clip(a, lo, hi):
    """np.clip via the min/max ufuncs (several times faster on small arrays)."""
    return np.minimum(np.maximum(a, lo), hi)


@dataclasses.dataclass(frozen=True)
class ControllerOutput:
    """One period's result: ``commands`` (2N+1,) counts and per-segment diagnostics (N,)."""

    commands: Array
    differential: Array
    saturated: npt.NDArray[np.bool_]
    integrator: Array


class CurvatureController:
    """Per-segment PI(D) curvature loop with feed-forward, anti-windup and pre-pressurisation.

    Args:
        params: Gains and ranges (``ControllerParams.from_robot``).
        n_segments: N; the controller drives 2N + 1 channels.
        prepressurised_segments: How many root segments get both channels pre-pressurised.
    """

    def __init__(self, params: ControllerParams, n_segments: int, prepressurised_segments: int):
        if n_segments < 1:
            raise ValueError(f"n_segments must be >= 1, got {n_segments}")
        if not 0 <= prepressurised_segments <= n_segments:
            raise ValueError(f"prepressurised_segments must be in [0, {n_segments}], "
                             f"got {prepressurised_segments}")
        self.p = params
        self.n = n_segments
        self.n_channels = 2 * n_segments + 1
        self.base = np.full(n_segments, params.cylinder_min)
        self.base[:prepressurised_segments] = params.prepressure
        self.n_pre = prepressurised_segments
        self.reset()

    @classmethod
    def from_robot(cls, robot: SoftArm) -> "CurvatureController":
        """Controller with the robot file's ``[controller]`` gains."""
        if 2 * robot.n_segments + 1 != robot.drive_cylinders:
            raise ValueError(f"{robot.name}: {robot.drive_cylinders} drive cylinders, expected "
                             f"2 per segment + gripper = {2 * robot.n_segments + 1}")
        return cls(ControllerParams.from_robot(robot), robot.n_segments, robot.prepressurised_segments)

    def reset(self, cylinders: npt.ArrayLike | None = None) -> None:
        """Forget integrators and filters; start the demands at ``cylinders`` (default minimum).

        Pass the device's current cylinder positions so the first demands do not jump; the
        root channels then ramp to the pre-pressure at the piston speed (arm initialisation).
        """
        if cylinders is None:
            cmd = np.full(self.n_channels, self.p.cylinder_min)
            cmd[-1] = self.p.gripper_open
        else:
            cmd = np.asarray(cylinders, dtype=float).copy()
            if cmd.shape != (self.n_channels,) or not np.all(np.isfinite(cmd)):
                raise ValueError(f"cylinders must be {self.n_channels} finite counts, got {cmd.shape}")
        self.commands = cmd
        self.integrator = np.zeros(self.n)
        self._dmeas = np.zeros(self.n)
        self._last_meas: Array | None = None

    @property
    def prepressurised(self) -> bool:
        """True once both channels of every root segment have reached the pre-pressure."""
        if self.n_pre == 0:
            return True
        ch = self.commands[: 2 * self.n_pre]
        return bool(np.all(ch >= self.p.prepressure - 1e-9))

    def differential_of(self, commands: npt.ArrayLike) -> Array:
        """Left minus right volume per segment for a (2N+1,) command vector."""
        c = np.asarray(commands, dtype=float)
        return c[0:2 * self.n:2] - c[1:2 * self.n:2]

    def step(self, kappa_target: npt.ArrayLike, kappa_meas: npt.ArrayLike, dt: float,
             kappa_rate_target: npt.ArrayLike | None = None,
             gripper_closed: bool = False) -> ControllerOutput:
        """One control period: new cylinder demands from target and measured curvatures.

        Args:
            kappa_target: (N,) reference curvature from trajGen, 1/m.
            kappa_meas: (N,) measured curvature (``fit_arm`` on motion capture), 1/m.
            dt: Time since the previous step, s (> 0; larger after skipped periods).
            kappa_rate_target: (N,) reference curvature rate for the lag lead, 1/(m s).
            gripper_closed: Demand the gripper cylinder closed (True) or open.
        """
        kt = np.asarray(kappa_target, dtype=float)
        km = np.asarray(kappa_meas, dtype=float)
        if kt.shape != (self.n,) or km.shape != (self.n,):
            raise ValueError(f"kappa_target and kappa_meas must have shape ({self.n},), "
                             f"got {kt.shape} and {km.shape}")
        if not (np.all(np.isfinite(kt)) and np.all(np.isfinite(km))):
            raise ValueError("kappa_target and kappa_meas must be finite")
        if not dt > 0:
            raise ValueError(f"dt must be > 0, got {dt}")
        p = self.p
        rate = np.zeros(self.n) if kappa_rate_target is None else np.asarray(kappa_rate_target, float)
        e = kt - km
        if self._last_meas is not None:
            alpha = dt / (p.derivative_filter_s + dt)
            self._dmeas += alpha * ((km - self._last_meas) / dt - self._dmeas)
        self._last_meas = km.copy()
        u = (p.counts_per_kappa * (kt + p.velocity_feedforward_s * rate)
             + p.kp * e + self.integrator - p.kd * self._dmeas)

        span = p.cylinder_max - self.base
        u_range = _clip(u, -span, span)
        want = np.empty(self.n_channels)
        want[0:2 * self.n:2] = self.base + np.maximum(u_range, 0.0)
        want[1:2 * self.n:2] = self.base + np.maximum(-u_range, 0.0)
        want[-1] = p.gripper_closed if gripper_closed else p.gripper_open
        slew = p.cylinder_rate * dt
        cmd = self.commands + _clip(want - self.commands, -slew, slew)
        applied = self.differential_of(cmd)

        excess = applied - u  # 0 unless a range or slew limit cut the demand
        sat = np.abs(excess) > 1e-9
        # Conditional integration: no integrating an error that pushes further into the limit.
        grow = ~sat | (np.sign(e) == np.sign(excess))
        new = self.integrator + dt * p.ki * e * grow
        # Back-calculation bleeds the integrator toward zero while saturated, never past zero
        # (the feed-forward term alone may saturate the slew; that must not wind I negative).
        bleed = dt * p.anti_windup_gain * excess
        bled = np.where(new * (new + bleed) <= 0, 0.0, new + bleed)
        self.integrator = np.where(sat & (np.sign(bleed) == -np.sign(new)), bled, new)
        bound = p.cylinder_max - p.cylinder_min
        np.minimum(np.maximum(self.integrator, -bound, out=self.integrator), bound, out=self.integrator)
        self.commands = cmd
        return ControllerOutput(cmd.copy(), applied, np.abs(applied - u) > 1e-9,
                                self.integrator.copy())

    def hold(self, gripper_closed: bool | None = None, dt: float = 0.0) -> ControllerOutput:
        """Keep the cylinder volumes where they are (STOP / tracking lost); integrators frozen.

        Holding the volumes holds the arm's shape. Only the gripper may still move (slewed),
        when ``gripper_closed`` is given. The derivative filter restarts on the next step.
        """
        cmd = self.commands.copy()
        if gripper_closed is not None and dt > 0:
            want = self.p.gripper_closed if gripper_closed else self.p.gripper_open
            slew = self.p.cylinder_rate * dt
            cmd[-1] += min(max(want - cmd[-1], -slew), slew)
        self.commands = cmd
        self._last_meas = None
        self._dmeas[:] = 0.0
        applied = self.differential_of(cmd)
        return ControllerOutput(cmd.copy(), applied, np.zeros(self.n, bool), self.integrator.copy())

    def steady_state_kappa(self, counts_per_kappa: float | None = None) -> Array:
        """Curvatures the current demands settle to for a plant of the given gain (diagnostics)."""
        c = self.p.counts_per_kappa if counts_per_kappa is None else counts_per_kappa
        return self.differential_of(self.commands) / c
