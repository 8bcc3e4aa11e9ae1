"""Grasping on both sides of the soft arm: why two stacked fingers, and the mirrored planner.

Katzschmann 2015 grasps only in the left quadrant: its gripper is one pleated finger that closes
toward the gripper's left (§5.3). Planning a right-quadrant object for that finger is possible
from the straight arm (the arm curls into an S so the finger's palm side faces the object), but
the S sweeps the arm through the object (the planner reports 30+ mm of sweep on the paper's
spots mirrored) and the grasps fail in simulation. §5.3 lists three ways out:

1. **two smaller grippers next to each other** -- chosen (robot file ``[gripper] fingers =
   "both"``). A lab builds it from what it has: two fingers cast in the paper's lost-wax mould at
   half height, stacked one above the other on the same palm, the lower one mounted upside down
   so it closes to the right, and a tee in the gripper's fluid line so the one gripper drive
   cylinder (channel 2N) closes both. Nothing else changes: still 2N + 1 channels, the same
   firmware, serial protocol and controller, the same arm; seen from above the pair is the
   paper's gripper (same length, width and palm), so each finger keeps the paper's capture
   region (Fig. 6), mirrored for the right one. Both fingers close on every grasp; the one on
   the object's side holds it, the other curls in the air on the far side. The cost: the
   half-height fingers hold tall objects lower down, the far finger's curl needs free table, and
   the pair adds a little mass at the tip (the arm drags < 40 g).
2. a flipped arm (roller supports on the top face, the arm turned 180° at its root): the gripper
   then closes to the right only, so a session can serve one side at a time and every change of
   side is a remount and a recalibration of the motion-capture markers -- the Fig. 7 experiment
   on both sides could not run in one go.
3. starting from an extreme curvature in the right quadrant: no hardware change, but the finger
   still closes to the left, so the arm must wrap around the object to face it with the palm
   (the S-shapes above, from a curled start instead); every grasp then starts from a strained
   arm (the planner's cost is the deformation from the start), and the left quadrant needs a
   move back through the straight pose first.

With a stacked pair the arm's kinematics and the right finger are the mirror image of the
left ones about the base's heading line (curvature kappa -> -kappa, the table reflected across
the line through the base along its heading). So a right-side grasp is planned by mirroring the
request, planning it with Algorithm 1 unchanged (:class:`core.planning.grasp.GraspPlanner`) and
mirroring the plan back (:func:`mirror_plan`): the paper's planner, its tolerances and its
clearance checks, with the approach circle now run clockwise (palm heading phi - pi/2) and the
object on the gripper's right. :class:`SidedPlanner` picks the side an object lies on (a
robot with the paper's single finger always plans for the left, as before), and
:func:`plan_grasp_sided` is the planning function the loop and the trials use.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np
import numpy.typing as npt

from core.planning.arm_model import wrap
from core.planning.feasibility import GraspRefused
from core.planning.grasp import GraspPlanner
from core.planning.obstacles import Obstacle
from core.planning.plan_types import GraspPlan, PlannerConfig
from core.robots import Side, SoftArm

Array = npt.NDArray[np.float64]

SIDES: tuple[Side, ...] = ("left", "right")


def _axis(robot: SoftArm) -> tuple[Array, Array, float]:
    """Base point, base heading unit vector and base heading of the mirror line."""
    b = np.asarray(robot.base_pose, dtype=float)
    return b[:2], np.array([math.cos(b[2]), math.sin(b[2])]), float(b[2])


@dataclasses.dataclass(frozen=True)
class MirrorLine:
    """The reflection across the base's heading line as one affine map, computed once.

    A point p goes to ``A p + t`` with ``A = [[cos 2h, sin 2h], [sin 2h, -cos 2h]]`` (h the
    base heading, ``t = b - A b`` for the base point b) and a heading theta to
    ``2 h - theta``; ``pose_map`` and ``pose_shift`` do both to (n, 3) poses in one product.
    """

    bx: float          # base point and heading h
    by: float
    h: float
    c2: float          # cos 2h, sin 2h
    s2: float
    tx: float
    ty: float
    pose_map: Array    # (3, 3): poses @ pose_map + pose_shift, before wrapping the heading
    pose_shift: Array  # (3,)

    @classmethod
    def of(cls, robot: SoftArm) -> MirrorLine:
        bx, by, h = (float(v) for v in robot.base_pose)
        c2, s2 = math.cos(2.0 * h), math.sin(2.0 * h)
        tx, ty = bx - (c2 * bx + s2 * by), by - (s2 * bx - c2 * by)
        pose_map = np.array([[c2, s2, 0.0], [s2, -c2, 0.0], [0.0, 0.0, -1.0]])
        return cls(bx, by, h, c2, s2, tx, ty, pose_map, np.array([tx, ty, 2.0 * h]))

    def point(self, x: float, y: float) -> tuple[float, float]:
        """One point reflected (plain floats)."""
        return (self.c2 * x + self.s2 * y + self.tx, self.s2 * x - self.c2 * y + self.ty)

    def side_of(self, x: float, y: float) -> Side:
        """As :func:`object_side`, on plain floats."""
        cross = math.cos(self.h) * (y - self.by) - math.sin(self.h) * (x - self.bx)
        return "right" if cross < 0.0 else "left"


def _wrap_in_place(a: Array) -> Array:
    """:func:`core.planning.arm_model.wrap` of a float array, in place (three ufunc calls)."""
    np.subtract(math.pi, a, out=a)
    np.mod(a, 2.0 * math.pi, out=a)
    return np.subtract(math.pi, a, out=a)


def mirror_xy(robot: SoftArm, xy: npt.ArrayLike) -> Array:
    """Points (..., 2) reflected across the base's heading line."""
    b, u, _ = _axis(robot)
    d = np.asarray(xy, dtype=float) - b
    along = d @ u
    return b + 2.0 * along[..., None] * u - d


def mirror_heading(robot: SoftArm, theta: npt.ArrayLike) -> Array:
    """Headings reflected across the base's heading line (wrapped to (-pi, pi])."""
    return np.asarray(wrap(2.0 * _axis(robot)[2] - np.asarray(theta, dtype=float)), float)


def object_side(robot: SoftArm, xy: npt.ArrayLike) -> Side:
    """The side of the base's heading line a point lies on (on the line: left)."""
    b, u, _ = _axis(robot)
    d = np.asarray(xy, dtype=float) - b
    return "right" if u[0] * d[1] - u[1] * d[0] < 0.0 else "left"


def mirror_plan(robot: SoftArm, plan: GraspPlan, line: MirrorLine | None = None) -> GraspPlan:
    """The plan of the mirrored request: curvatures negated, points and headings reflected,
    the side swapped; radii, clearances and solver figures are unchanged by a reflection.

    Runs once per right-side plan, so it is a handful of array operations on the whole plan
    (``line``: the robot's :class:`MirrorLine`, when the caller keeps it) and a field copy of
    the frozen plan rather than :func:`dataclasses.replace`, which re-runs ``__init__`` over
    every field.
    """
    m = MirrorLine.of(robot) if line is None else line
    poses = plan.palm_poses @ m.pose_map + m.pose_shift
    _wrap_in_place(poses[:, 2])
    cx, cy = plan.center.tolist()
    out = object.__new__(GraspPlan)
    fields = out.__dict__
    fields.update(plan.__dict__)
    fields.update(
        center=np.array(m.point(cx, cy)), kappa_meas=-plan.kappa_meas, kappas=-plan.kappas,
        palm_poses=poses, phis=_wrap_in_place(2.0 * m.h - plan.phis),
        side="right" if plan.side == "left" else "left")
    if plan.obstacles:
        fields["obstacles"] = tuple(mirror_obstacle(robot, o, m) for o in plan.obstacles)
    return out


def mirror_obstacle(robot: SoftArm, obstacle: Obstacle, line: MirrorLine | None = None
                    ) -> Obstacle:
    """An obstacle disk reflected across the base's heading line (name and radius kept)."""
    x, y = (MirrorLine.of(robot) if line is None else line).point(obstacle.x, obstacle.y)
    return dataclasses.replace(obstacle, x=x, y=y)


class SidedPlanner:
    """Algorithm 1 on the side of the arm the object lies on (see the module docstring).

    Same ``plan`` call as :class:`~core.planning.grasp.GraspPlanner` plus ``side``; ``model``
    and ``config`` are the wrapped planner's.
    """

    def __init__(self, robot: SoftArm, config: PlannerConfig | None = None):
        self.robot = robot
        self.left = GraspPlanner(robot, config)
        self.model = self.left.model
        self.config = self.left.config
        self.mirror = MirrorLine.of(robot)

    def side_for(self, center: npt.ArrayLike) -> Side:
        """The side a grasp of an object at ``center`` is planned on."""
        if "right" not in self.robot.gripper.sides:
            return "left"
        x, y = np.asarray(center, dtype=float).tolist()
        return self.mirror.side_of(x, y)

    def plan(self, kappa_meas: npt.ArrayLike, center: npt.ArrayLike, radius: float, *,
             side: Side | None = None, delta_d: float | None = None,
             weights: npt.ArrayLike | None = None,
             obstacles: tuple[Obstacle, ...] | list[Obstacle] = (),
             clearance: float = 0.0) -> GraspPlan:
        """Plan on ``side`` (default: the side the object lies on; see :meth:`side_for`).

        Raises:
            GraspRefused: as :meth:`GraspPlanner.plan`, or ``side`` is one the gripper cannot
                close toward.
        """
        ctr = np.asarray(center, dtype=float)
        if ctr.shape != (2,):
            raise GraspRefused("bad_input", f"The object centre must be (x, y), got {ctr!r}.")
        side = self.side_for(ctr) if side is None else side
        if side not in SIDES:
            raise GraspRefused("bad_input", f"side must be 'left' or 'right', got {side!r}.")
        if side not in self.robot.gripper.sides:
            raise GraspRefused("wrong_side", "This gripper closes to its left only (robot file "
                               "[gripper] fingers = \"left\"): it cannot grasp on the right.")
        if side == "left":
            return self.left.plan(kappa_meas, ctr, radius, delta_d=delta_d, weights=weights,
                                  obstacles=obstacles, clearance=clearance)
        km = np.asarray(kappa_meas, dtype=float)
        m = self.mirror
        plan = self.left.plan(-km, m.point(*ctr.tolist()), radius, delta_d=delta_d,
                              weights=weights, clearance=clearance,
                              obstacles=[mirror_obstacle(self.robot, o, m) for o in obstacles])
        return mirror_plan(self.robot, plan, m)


class _ByIdentity:
    """Hashable by identity, so a planner can be memoised per robot object."""

    def __init__(self, obj: SoftArm):
        self.obj = obj

    def __hash__(self) -> int:
        return id(self.obj)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _ByIdentity) and other.obj is self.obj


@functools.lru_cache(maxsize=4)
def _memoised(key: _ByIdentity) -> SidedPlanner:
    return SidedPlanner(key.obj)


def _planner_for(robot: SoftArm) -> SidedPlanner:
    return _memoised(_ByIdentity(robot))


def plan_grasp_sided(robot: SoftArm, kappa_meas: npt.ArrayLike, center: npt.ArrayLike,
                     radius: float, *, side: Side | None = None, delta_d: float | None = None,
                     weights: npt.ArrayLike | None = None,
                     obstacles: tuple[Obstacle, ...] | list[Obstacle] = (),
                     clearance: float = 0.0) -> GraspPlan:
    """:func:`core.planning.grasp.plan_grasp` on the object's side of the arm (a memoised
    :class:`SidedPlanner` per robot), around ``obstacles`` keeping ``clearance`` (m)."""
    return _planner_for(robot).plan(kappa_meas, center, radius, side=side, delta_d=delta_d,
                                    weights=weights, obstacles=obstacles, clearance=clearance)
