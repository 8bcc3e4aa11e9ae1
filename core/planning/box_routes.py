"""A collision-free way for the extensible arm from where it is to a tip-IK solution, past boxes.

The console moves the arm to a tip target along a straight line in rack space (the hold-to-run
set-point and the runner's follower both interpolate the posture linearly; Delta = M L - Delta_0
is affine, so that is one line in Delta too). With box obstacles the IK's answer may be clear
while that line is not (the arm swings through a shelf on its way), so :func:`clear_route`
checks the line by dense forward kinematics (:func:`box_clearance.motion_clearance`) and, when
it is blocked, tries a few detours through simpler postures -- the start and the goal with
their bends kept and their extension taken back to the shortest racks, the two straightened
(extension kept), and the straight retracted arm -- as chains of straight lines, keeping the
first (shortest) chain that is clear. When none
is, :class:`~core.planning.paths.BlockedPath` says which box and how close the direct line
comes. A start that is already too close to a box may only move away: its legs need at least
the smaller of the clearance and the start's own.

:func:`reach_clear` is the console's one call (it runs in a worker process): the IK with the
boxes, then the route to its answer.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from core.kinematics import box_clearance as bc
from core.kinematics import delta as dk
from core.kinematics.delta_ik import TipIKResult, solve_tip_ik
from core.planning.paths import BlockedPath
from core.robot_sections import IKSettings

if TYPE_CHECKING:
    from core.robots import ExtensibleArm

Array = npt.NDArray[np.float64]


def retracted(robot: ExtensibleArm, delta: npt.ArrayLike) -> Array:
    """``delta`` (n, 3) with each segment's bend kept and its racks as short as they go."""
    d = np.asarray(delta, dtype=float).copy()
    L = dk.robot_rack_lengths(robot, d)
    shift = L.min(axis=-1) - robot.rack_min                      # every rack down by this
    d[..., 2] -= shift
    return dk.delta_from_actuators(dk.limit_rack_lengths(robot, dk.robot_rack_lengths(robot, d)),
                                   robot.phi, robot.L0)


def straightened(delta: npt.ArrayLike) -> Array:
    """``delta`` (n, 3) with every bend taken out and the extensions kept."""
    d = np.asarray(delta, dtype=float).copy()
    d[..., :2] = 0.0
    return d


def _candidates(robot: ExtensibleArm, start: Array, goal: Array) -> list[list[Array]]:
    """Chains of via postures, shortest first (the goal closes every chain)."""
    a, b = retracted(robot, start), retracted(robot, goal)
    sa, sg = straightened(start), straightened(goal)
    home = np.zeros_like(start)
    vias = [[], [a], [b], [sa], [sg], [home], [a, b], [sa, sg], [a, home, b], [sa, home, sg],
            [sa, b], [a, sg], [a, home, sg], [sa, home, b]]
    return [via + [goal] for via in vias]


@dataclasses.dataclass(frozen=True)
class Route:
    """Postures to move through in turn (the last is the goal), and the smallest clearance of
    the arm's body surface along the straight rack-space lines through them (m; inf without
    boxes)."""

    postures: tuple[Array, ...]
    clearance: float
    nearest_box: str = ""


def clear_route(robot: ExtensibleArm, start: npt.ArrayLike, goal: npt.ArrayLike,
                boxes: Sequence[bc.Box], clearance: float) -> Route:
    """Straight rack-space legs from ``start`` to ``goal`` (Delta, (n, 3) each) that keep the
    arm's body ``clearance`` from every box (its surface: the backbone's distance minus the
    robot file's ``body_radius``; see the module).

    Raises:
        BlockedPath: no candidate route is clear; names the box and how close the direct
            line comes.
    """
    s = np.asarray(start, dtype=float)
    g = np.asarray(goal, dtype=float)
    if not boxes:
        return Route((g,), float("inf"))
    need = min(clearance, bc.clearance_of(robot, s, boxes).distance - 1e-4)
    direct = None
    for via in _candidates(robot, s, g):
        chain = np.stack([s] + via)
        found = bc.motion_clearance(robot, dk.robot_rack_lengths(robot, chain), boxes,
                                    below=None if direct is None else need)
        if direct is None:
            direct = found
        if found.clear_of(need):
            return Route(tuple(via), found.distance, found.box)
    assert direct is not None
    raise BlockedPath(f"no collision-free move from the current posture to the solution: the "
                      f"direct move {direct.describe()}, and no detour through a straightened or "
                      f"retracted posture keeps {clearance * 1e3:.1f} mm")


@dataclasses.dataclass(frozen=True)
class ClearReach:
    """The IK answer with boxes and the route to it; ``refusal`` says why not to move ("" to go)."""

    result: TipIKResult
    route: Route | None
    refusal: str


def reach_clear(robot: ExtensibleArm, target: npt.ArrayLike, start: npt.ArrayLike, *,
                restarts: bool, settings: IKSettings | None, boxes: Sequence[bc.Box],
                clearance: float) -> ClearReach:
    """Tip IK to ``target`` keeping ``clearance`` from ``boxes``, warm-started at ``start``
    (n, 3), and a clear route there; the refusal names the box when there is none."""
    res = solve_tip_ik(robot, target, start, restarts=restarts, settings=settings, boxes=boxes,
                       clearance=clearance)
    if res.refusal:
        return ClearReach(res, None, res.refusal)
    if not res.clear:
        return ClearReach(res, None, "no collision-free posture was found")
    try:
        route = clear_route(robot, start, res.delta, boxes, clearance)
    except BlockedPath as exc:
        return ClearReach(res, None, str(exc))
    return ClearReach(res, route, "")
