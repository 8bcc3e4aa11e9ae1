"""Typed robot-file sections shared by core and hw_bridge: IK, paths, bridge link and emulator."""

from __future__ import annotations

import dataclasses
from typing import Protocol

from core.robot_schema import Section


class ExtensibleSections(Protocol):
    """The loaded sections ``from_robot`` returns: :class:`core.robots.ExtensibleArm` has them.

    A protocol rather than ``ExtensibleArm`` itself, which is built from these classes (so
    naming it here would close an import circle with :mod:`core.robots`).
    """

    @property
    def ik(self) -> IKSettings: ...

    @property
    def paths(self) -> PathSettings: ...


@dataclasses.dataclass(frozen=True)
class IKSettings:
    """Tip-IK solver settings (robot file ``[ik]``; every key optional).

    Attributes:
        tolerance: A target is reachable when the final error is <= this (m).
        goal_tolerance: The iteration stops early once the error is <= this (m).
        damping: Initial Levenberg-Marquardt damping lambda.
        max_iterations: Iterations per start.
        restart_seeds: Number of low-discrepancy seeds added to the structured restart seeds
            (0 disables restarts from those).
        stall_step: A start stops when its error improves by less than this per iteration (m).
        stall_ratio: ... or by less than this fraction of its error (a local minimum).
        polish_iterations: SLSQP iterations spent polishing the best configuration of a target
            left above ``tolerance`` (0 disables; see :func:`_polish`).
    """

    tolerance: float = 1e-3
    goal_tolerance: float = 1e-6
    damping: float = 1e-3
    max_iterations: int = 60
    restart_seeds: int = 12
    stall_step: float = 1e-9
    stall_ratio: float = 1e-4
    polish_iterations: int = 50

    @classmethod
    def read(cls, sec: Section) -> "IKSettings":
        """Defaults overridden by the robot file's ``[ik]`` table (every key optional)."""
        d = cls()
        s = cls(
            tolerance=sec.num("tolerance", lo=0, hi=1.0, strict_lo=True, default=d.tolerance),
            goal_tolerance=sec.num("goal_tolerance", lo=0, hi=1.0, strict_lo=True,
                                   default=d.goal_tolerance),
            damping=sec.num("damping", lo=0, hi=1e6, strict_lo=True, default=d.damping),
            max_iterations=sec.integer("max_iterations", lo=1, hi=1000, default=d.max_iterations),
            restart_seeds=sec.integer("restart_seeds", lo=0, hi=1000, default=d.restart_seeds),
            stall_step=sec.num("stall_step", lo=0, hi=1.0, strict_lo=True, default=d.stall_step),
            stall_ratio=sec.num("stall_ratio", lo=0, hi=1.0, strict_lo=True, default=d.stall_ratio),
            polish_iterations=sec.integer("polish_iterations", lo=0, hi=1000,
                                          default=d.polish_iterations),
        )
        if s.goal_tolerance > s.tolerance:
            raise sec.error("goal_tolerance", f"must be <= ik.tolerance ({s.tolerance:g}), "
                                              f"got {s.goal_tolerance:g}")
        sec.finish()
        return s

    @classmethod
    def from_robot(cls, robot: ExtensibleSections) -> "IKSettings":
        """The robot file's ``[ik]`` settings (validated when the file was loaded)."""
        return robot.ik


@dataclasses.dataclass(frozen=True)
class PathSettings:
    """Sampling settings (robot file ``[paths]``; every key optional).

    Attributes:
        rate_hz: Output sample rate (the control loop's rate).
        spacing: Largest tip travel between IK samples (m).
        limit_margin: Fraction of the tip, rack and motor speed limits the time law plans for.
        jump_ratio: Rack travel / tip travel above which an interval is bisected.
        max_bisections: How often an interval may be bisected.
        retry_spacing: Tip travel between restart attempts while the target is out of reach of
            the branch being followed (m).
    """

    rate_hz: float = 100.0
    spacing: float = 0.001
    limit_margin: float = 0.98
    jump_ratio: float = 20.0
    max_bisections: int = 6
    retry_spacing: float = 0.01

    @classmethod
    def read(cls, sec: Section) -> "PathSettings":
        """Defaults overridden by the robot file's ``[paths]`` table (every key optional)."""
        d = cls()
        s = cls(
            rate_hz=sec.num("rate_hz", lo=0, hi=10_000, strict_lo=True, default=d.rate_hz),
            spacing=sec.num("spacing", lo=1e-5, hi=1.0, default=d.spacing),
            limit_margin=sec.num("limit_margin", lo=0, hi=1, strict_lo=True,
                                 default=d.limit_margin),
            jump_ratio=sec.num("jump_ratio", lo=0, hi=1e6, strict_lo=True, default=d.jump_ratio),
            max_bisections=sec.integer("max_bisections", lo=0, hi=12, default=d.max_bisections),
            retry_spacing=sec.num("retry_spacing", lo=1e-5, hi=10.0, default=d.retry_spacing),
        )
        sec.finish()
        return s

    @classmethod
    def from_robot(cls, robot: ExtensibleSections) -> "PathSettings":
        """The robot file's ``[paths]`` settings (validated when the file was loaded)."""
        return robot.paths


@dataclasses.dataclass(frozen=True)
class BridgeSection:
    """``[bridge]``: the serial link to the device (docs/protocol.md); times in milliseconds.

    ``hw_bridge.config.BridgeConfig`` turns this into the link's settings in seconds.
    """

    baud: int
    rate_hz: float
    watchdog_ms: float
    link_timeout_ms: float
    hello_timeout_ms: float
    config_retries: int
    config_retry_ms: float
    velocities: bool

    @classmethod
    def read(cls, sec: Section) -> "BridgeSection":
        """Read and check ``[bridge]``."""
        b = cls(
            baud=sec.integer("baud", lo=300, hi=100_000_000),
            rate_hz=sec.num("rate_hz", lo=0, hi=10_000, strict_lo=True),
            watchdog_ms=sec.num("watchdog_ms", lo=0, hi=60_000, strict_lo=True),
            link_timeout_ms=sec.num("link_timeout_ms", lo=0, hi=60_000, strict_lo=True),
            hello_timeout_ms=sec.num("hello_timeout_ms", lo=0, hi=60_000, strict_lo=True),
            config_retries=sec.integer("config_retries", lo=0, hi=100),
            config_retry_ms=sec.num("config_retry_ms", lo=0, hi=60_000, strict_lo=True),
            velocities=sec.flag("velocities", default=False),
        )
        sec.finish()
        return b


@dataclasses.dataclass(frozen=True)
class EmulatorSection:
    """``[emulator]``: the device emulator's plant (hw_bridge/emulator.py).

    Attributes:
        motor_speed_counts: Speed limit of every emulated motor / drive cylinder (counts/s).
        counts_per_kappa, tau, mocap_port, mocap_rate_hz: Soft arm only: curvature-plant gain
            (differential counts per 1/m) and lag (s), and the emulated motion capture's UDP
            port on 127.0.0.1 and frame rate (Hz); None for the extensible arm.
    """

    motor_speed_counts: float
    counts_per_kappa: float | None = None
    tau: float | None = None
    mocap_port: int | None = None
    mocap_rate_hz: float | None = None

    @classmethod
    def read(cls, sec: Section, *, planar: bool) -> "EmulatorSection":
        """Read and check ``[emulator]``; the soft arm's plant and mocap keys only if ``planar``."""
        speed = sec.num("motor_speed_counts", lo=0, hi=1e9, strict_lo=True)
        if not planar:
            sec.finish()
            return cls(motor_speed_counts=speed)
        e = cls(
            motor_speed_counts=speed,
            counts_per_kappa=sec.num("counts_per_kappa", lo=0, hi=1e9, strict_lo=True),
            tau=sec.num("tau", lo=0, hi=100.0, strict_lo=True),
            mocap_port=sec.integer("mocap_port", lo=1, hi=65535),
            mocap_rate_hz=sec.num("mocap_rate_hz", lo=0, hi=10_000, strict_lo=True),
        )
        sec.finish()
        return e
