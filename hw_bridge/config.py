"""Bridge and emulator settings from the robot TOML (``[bridge]``, ``[emulator]``), not code.

:func:`core.robots.load` reads and checks both sections (``robot.bridge``, ``robot.emulator``);
this module only turns them into the link's units (seconds) and channel count.
"""

from __future__ import annotations

import dataclasses

from core.robots import ExtensibleArm, Robot, SoftArm


def n_channels(robot: Robot) -> int:
    """Motors (extensible arm) or drive cylinders (soft arm) on the serial link."""
    if isinstance(robot, ExtensibleArm):
        return robot.n_motors
    if isinstance(robot, SoftArm):
        return robot.drive_cylinders
    raise TypeError(f"unsupported robot {robot!r}")


@dataclasses.dataclass(frozen=True)
class BridgeConfig:
    """Host-side link settings; times in seconds."""

    n_motors: int
    baud: int
    rate_hz: float
    watchdog_s: float
    link_timeout_s: float
    hello_timeout_s: float
    config_retries: int
    config_retry_s: float
    velocities: bool

    @property
    def period_s(self) -> float:
        """Streaming period of DEMAND and STATE."""
        return 1.0 / self.rate_hz

    @classmethod
    def from_robot(cls, robot: Robot, *, n_motors: int | None = None) -> "BridgeConfig":
        """From ``robot.bridge``; ``n_motors`` overrides the robot's channel count (benchmarks)."""
        b = robot.bridge
        return cls(
            n_motors=n_channels(robot) if n_motors is None else n_motors,
            baud=b.baud,
            rate_hz=b.rate_hz,
            watchdog_s=b.watchdog_ms / 1000.0,
            link_timeout_s=b.link_timeout_ms / 1000.0,
            hello_timeout_s=b.hello_timeout_ms / 1000.0,
            config_retries=b.config_retries,
            config_retry_s=b.config_retry_ms / 1000.0,
            velocities=b.velocities,
        )


@dataclasses.dataclass(frozen=True)
class EmulatorConfig:
    """Device-emulator plant settings (``[emulator]``)."""

    motor_speed_counts: float
    counts_per_kappa: float | None = None
    tau: float | None = None
    mocap_port: int | None = None
    mocap_rate_hz: float | None = None

    @classmethod
    def from_robot(cls, robot: Robot) -> "EmulatorConfig":
        """From ``robot.emulator``; the soft arm also has its curvature-plant and mocap fields."""
        e = robot.emulator
        return cls(motor_speed_counts=e.motor_speed_counts, counts_per_kappa=e.counts_per_kappa,
                   tau=e.tau, mocap_port=e.mocap_port, mocap_rate_hz=e.mocap_rate_hz)
