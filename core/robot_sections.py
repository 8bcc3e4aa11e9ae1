"""Typed robot-file sections shared by core and hw_bridge: IK, paths, bridge link and emulator."""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Any, Mapping

if TYPE_CHECKING:
    from core.robots import ExtensibleArm


@dataclasses.dataclass(frozen=True)
class IKSettings:
    """Solver settings (robot file ``[ik]``; every key optional).

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
    def from_robot(cls, robot: "ExtensibleArm") -> "IKSettings":
        """Defaults overridden by the robot file's ``[ik]`` table; bad values raise ValueError."""
        table: Mapping[str, Any] = robot.raw.get("ik", {}) if robot.raw else {}
        kwargs: dict[str, Any] = {}
        for field in dataclasses.fields(cls):
            if field.name not in table:
                continue
            value = table[field.name]
            if field.type in ("int", int):
                if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                    raise ValueError(f"ik.{field.name}: must be an integer >= 0, got {value!r}")
            elif (isinstance(value, bool) or not isinstance(value, (int, float))
                  or not math.isfinite(value) or value <= 0):
                raise ValueError(f"ik.{field.name}: must be a finite number > 0, got {value!r}")
            kwargs[field.name] = value
        unknown = set(table) - {f.name for f in dataclasses.fields(cls)}
        if unknown:
            raise ValueError(f"ik: unknown keys {sorted(unknown)}")
        settings = cls(**kwargs)
        if settings.max_iterations < 1:
            raise ValueError("ik.max_iterations: must be >= 1")
        if settings.goal_tolerance > settings.tolerance:
            raise ValueError(f"ik.goal_tolerance: must be <= ik.tolerance ({settings.tolerance:g}), "
                             f"got {settings.goal_tolerance:g}")
        return settings


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
    def from_robot(cls, robot: "ExtensibleArm") -> "PathSettings":
        """Defaults overridden by the robot file's ``[paths]`` table; bad values raise ValueError."""
        table: Mapping[str, Any] = robot.raw.get("paths", {}) if robot.raw else {}
        names = {f.name for f in dataclasses.fields(cls)}
        if set(table) - names:
            raise ValueError(f"paths: unknown keys {sorted(set(table) - names)}")
        kwargs: dict[str, Any] = {}
        for name, value in table.items():
            if name == "max_bisections":
                if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                    raise ValueError(f"paths.{name}: must be an integer >= 0, got {value!r}")
            elif (isinstance(value, bool) or not isinstance(value, (int, float))
                  or not math.isfinite(value) or value <= 0):
                raise ValueError(f"paths.{name}: must be a finite number > 0, got {value!r}")
            kwargs[name] = value
        settings = cls(**kwargs)
        if settings.limit_margin > 1:
            raise ValueError(f"paths.limit_margin: must be <= 1, got {settings.limit_margin}")
        return settings
