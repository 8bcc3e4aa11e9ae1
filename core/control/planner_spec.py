"""Planning functions named by ``"package.module:function"`` strings, so a planner is a setting.

The trials' ``--planner`` and the loop's planning worker process take such a name; the function
takes ``(robot, kappa_meas, center, radius)`` (and ``obstacles=``, ``clearance=`` keywords when
the request has obstacles, :func:`plan_request`) and returns a plan (see
:func:`core.planning.sides.plan_grasp_sided`, the default: Algorithm 1 on the side of the arm
the object lies on, for a gripper that closes to both sides).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any, Callable

if TYPE_CHECKING:
    from core.control.grasp_place import PlanRequest

DEFAULT_PLANNER = "core.planning.sides:plan_grasp_sided"


def resolve(spec: str) -> Callable[..., Any]:
    """``"package.module:function"`` -> the function."""
    module, _, name = spec.partition(":")
    if not module or not name:
        raise ValueError(f"expected 'module:function', got {spec!r}")
    return getattr(importlib.import_module(module), name)


def plan_request(fn: Callable[..., Any], robot: Any, req: "PlanRequest") -> Any:
    """``fn`` (a planning function as above) called for a state machine's request: around the
    request's obstacles with its clearance when it has any (the first plan and every re-plan
    alike), else with the four positional arguments only (a planner that knows no obstacles
    still works without them)."""
    if req.obstacles:
        return fn(robot, req.kappa, req.center, req.radius, obstacles=req.obstacles,
                  clearance=req.clearance)
    return fn(robot, req.kappa, req.center, req.radius)
