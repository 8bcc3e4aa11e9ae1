"""Bridge and emulator settings read from the robot TOML (``[bridge]``, ``[emulator]``), not code."""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping

from core.robots import ExtensibleArm, Robot, RobotFileError, SoftArm


def _section(robot: Robot, name: str) -> Mapping[str, Any]:
    table = robot.raw.get(name)
    if not isinstance(table, Mapping):
        raise RobotFileError(f"{robot.source.name}: [{name}]: missing")
    return table


def _num(table: Mapping[str, Any], section: str, key: str, *, positive: bool = True) -> float:
    value = table.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise RobotFileError(f"{section}.{key}: must be a finite number, got {value!r}")
    if positive and value <= 0:
        raise RobotFileError(f"{section}.{key}: must be > 0, got {value!r}")
    return float(value)


def _int(table: Mapping[str, Any], section: str, key: str) -> int:
    value = table.get(key)
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise RobotFileError(f"{section}.{key}: must be an integer >= 0, got {value!r}")
    return value


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
        """Read ``[bridge]``; ``n_motors`` overrides the robot's channel count (benchmarks)."""
        t = _section(robot, "bridge")
        velocities = t.get("velocities", False)
        if not isinstance(velocities, bool):
            raise RobotFileError(f"bridge.velocities: must be true or false, got {velocities!r}")
        return cls(
            n_motors=n_channels(robot) if n_motors is None else n_motors,
            baud=_int(t, "bridge", "baud"),
            rate_hz=_num(t, "bridge", "rate_hz"),
            watchdog_s=_num(t, "bridge", "watchdog_ms") / 1000.0,
            link_timeout_s=_num(t, "bridge", "link_timeout_ms") / 1000.0,
            hello_timeout_s=_num(t, "bridge", "hello_timeout_ms") / 1000.0,
            config_retries=_int(t, "bridge", "config_retries"),
            config_retry_s=_num(t, "bridge", "config_retry_ms") / 1000.0,
            velocities=velocities,
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
        """Read ``[emulator]``; the soft arm also needs its curvature-plant and mocap fields."""
        t = _section(robot, "emulator")
        speed = _num(t, "emulator", "motor_speed_counts")
        if isinstance(robot, SoftArm):
            return cls(
                motor_speed_counts=speed,
                counts_per_kappa=_num(t, "emulator", "counts_per_kappa"),
                tau=_num(t, "emulator", "tau"),
                mocap_port=_int(t, "emulator", "mocap_port"),
                mocap_rate_hz=_num(t, "emulator", "mocap_rate_hz"),
            )
        return cls(motor_speed_counts=speed)
