"""Planning functions named by ``"package.module:function"`` strings, so a planner is a setting.

The trials' ``--planner`` and the loop's planning worker process take such a name; the function
takes ``(robot, kappa_meas, center, radius)`` and returns a plan (see
:func:`core.planning.sides.plan_grasp_sided`, the default: Algorithm 1 on the side of the arm
the object lies on, for a gripper that closes to both sides).
"""

from __future__ import annotations

import importlib
from typing import Any, Callable

DEFAULT_PLANNER = "core.planning.sides:plan_grasp_sided"


def resolve(spec: str) -> Callable[..., Any]:
    """``"package.module:function"`` -> the function."""
    module, _, name = spec.partition(":")
    if not module or not name:
        raise ValueError(f"expected 'module:function', got {spec!r}")
    return getattr(importlib.import_module(module), name)
