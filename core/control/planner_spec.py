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
    still works without them).

    With obstacles and a bin (``req.bin``) the plan also gets its carry to the bin around
    them (:func:`core.control.carry.with_carry`); a request with a given plan (``req.plan``,
    an executed plan) only gets that carry, ``fn`` is not called."""
    if req.plan is not None:
        plan = req.plan
    elif req.obstacles:
        plan = fn(robot, req.kappa, req.center, req.radius, obstacles=req.obstacles,
                  clearance=req.clearance)
    else:
        return fn(robot, req.kappa, req.center, req.radius)
    if req.obstacles and req.bin is not None:
        from core.control.carry import with_carry
        return with_carry(robot, plan, req)
    return plan
