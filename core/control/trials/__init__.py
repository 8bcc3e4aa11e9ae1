"""Headless grasp-and-place trials on the simulated arm, reproducing the paper's experiment (§5.2).

Each trial builds a seeded :class:`~core.control.sim.SoftArmSim`, places the object (the user's
placement is uniform within +-1 mm of the spot, as in the paper), arms the controller and runs
the full grasp-and-place through the control cycle on a simulated clock
(:class:`core.control.sim_loop.SimLoop`, the loop runner's order and timing without a thread),
until ``released``, ``stopped`` or a time limit. Success: released, and the object put down within
``bin.drop_radius_m`` of the bin drop point (where the object sits when the gripper is at the
bin). :func:`paper_locations` are the five spots A-E used with the paper's 3.3 cm object;
:func:`sided_objects` mirrors them to the right side of the arm (A'-E', for a gripper with
fingers on both sides: :mod:`core.planning.sides`) and :func:`per_side` counts successes per side.
:func:`run_trials` runs a batch through any ``map`` (the builtin: in this process; a process
pool's ``map``: in parallel - the caller owns the pool). :func:`run_row_trial` takes several
objects in a row to the bin in one run (:mod:`core.control.row`), e.g. objects drawn by
:func:`draw_row_objects` on one side of the arm or alternating (the released count per side).

Command line: ``python -m core.control.trials`` (:mod:`core.control.trials.__main__`).
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from core.control.grasp_place import Phase, immediate
from core.control.params import BinParams
from core.control.planner_spec import DEFAULT_PLANNER, plan_request, resolve
from core.control.row import ObjectOutcome, ObjectRow, RowObject, bin_at, run_row
from core.control.sim import SoftArmSim
from core.control.sim_loop import SimLoop
from core.control.stack import ControlStack
from core.kinematics.planar import forward_kinematics, point_in_frame
from core.planning.feasibility import GraspRefused
from core.planning.obstacles import DEFAULT_CLEARANCE
from core.planning.sides import mirror_xy, object_side
from core.robots import Side, SoftArm, load

PLACEMENT_TOLERANCE_M = 0.001  # the paper: user placement within +-1 mm
ROW_OBJECT_TIME_LIMIT_S = 300.0  # a row's object: carried around the others it can take ~150 s


def paper_locations() -> dict[str, tuple[float, float]]:
    """Spots A-E across the left quadrant (m), spread over the reachable workspace like Fig. 7.

    From near the base's side to far up the workspace: A low and far left, B mid-left, C close
    in, D up and left, E high near the arm's straight line. All are at least a gripper length
    away from the straight arm (so the approach is not trivial) and feasible for the planner.
    """
    return {"A": (-0.26, 0.10), "B": (-0.22, 0.20), "C": (-0.13, 0.17),
            "D": (-0.16, 0.28), "E": (-0.08, 0.33)}


SIDE_CHOICES = ("left", "right", "both")


def sided_objects(robot: SoftArm, objects: Sequence[tuple[str, Sequence[float]]],
                  side: str) -> list[tuple[str, tuple[float, float, float]]]:
    """The batch's objects for ``side``: ``left`` as given (the paper's experiment), ``right``
    their mirror images across the base's heading line (label + "'"), ``both`` each object
    and then each mirror image (:mod:`core.planning.sides`)."""
    if side not in SIDE_CHOICES:
        raise ValueError(f"side must be one of {', '.join(SIDE_CHOICES)}, got {side!r}")
    given = [(lab, (float(o[0]), float(o[1]), float(o[2]))) for lab, o in objects]
    mirrored = []
    for lab, (x, y, r) in given:
        mx, my = mirror_xy(robot, (x, y))
        mirrored.append((f"{lab}'", (float(mx), float(my), r)))
    return {"left": given, "right": mirrored, "both": given + mirrored}[side]


def per_side(results: Sequence["TrialResult"]) -> dict[str, dict[str, int]]:
    """``{"left": {"successes": k, "trials": n}, "right": ...}`` for the sides that ran."""
    out: dict[str, dict[str, int]] = {}
    for r in results:
        d = out.setdefault(r.side, {"successes": 0, "trials": 0})
        d["trials"] += 1
        d["successes"] += int(r.success)
    return {s: out[s] for s in ("left", "right") if s in out}


@dataclasses.dataclass(frozen=True)
class TrialResult:
    """One trial (JSON fields first)."""

    object: list[float]
    success: bool
    failure: str | None
    approach_s: float
    return_s: float
    label: str = ""
    seed: int = 0
    sim_s: float = 0.0
    wall_s: float = 0.0
    ticks: int = 0
    replans: int = 0
    stalls: int = 0
    occlusions: int = 0
    work_ms_p99: float = 0.0
    final_object: tuple[float, float] | None = None
    side: str = "left"  # the side of the arm the object was placed on


def bin_drop_point(robot: SoftArm, radius: float, bin_params: BinParams | None = None,
                   side: Side = "left") -> np.ndarray:
    """Where the grasped object sits when the arm is at the bin configuration (the robot's
    ``[bin]`` unless ``bin_params`` is given), held by the finger closing toward ``side``."""
    b = BinParams.from_robot(robot) if bin_params is None else bin_params
    tip = forward_kinematics(b.kappa_for(side), robot.lengths, robot.base_pose)[-1]
    normal = 2 * robot.gripper.g_off + radius
    return point_in_frame(tip, (robot.gripper.w_off_along, -normal if side == "right" else normal))


def run_trial(robot: SoftArm, obj: Sequence[float], seed: int, *, label: str = "",
              planner: str = DEFAULT_PLANNER, time_limit_s: float = 150.0,
              sim_overrides: dict[str, Any] | None = None,
              observe: Callable[[Any], Any] | None = None) -> TrialResult:
    """One headless grasp-and-place trial on the simulated clock; ``observe(telemetry)`` (if
    given) sees every tick's telemetry (``core.labdata.trial_recording`` records them)."""
    x, y, r = (float(v) for v in obj)
    rng = np.random.default_rng([seed, 7])
    plan_fn: Callable[..., Any] = resolve(planner)
    sim = SoftArmSim(robot, seed=seed)
    if sim_overrides:
        sim.p = sim.p.replace(**sim_overrides)
    sim.place_object(x + rng.uniform(-PLACEMENT_TOLERANCE_M, PLACEMENT_TOLERANCE_M),
                     y + rng.uniform(-PLACEMENT_TOLERANCE_M, PLACEMENT_TOLERANCE_M), r)
    on_plan = getattr(observe, "on_plan", None)  # a recorder also takes each plan made

    def planned(req: Any) -> Any:
        try:
            plan = plan_request(plan_fn, robot, req)
        except Exception as exc:
            if on_plan is not None:
                on_plan(None, str(exc))
            raise
        if on_plan is not None:
            on_plan(plan, None)
        return plan

    stack = ControlStack(robot, 0.01, immediate(planned))
    loop = SimLoop(sim, stack, 0.01)
    wall = time.perf_counter()
    watch = (lambda c: bool(observe(c))) if observe else None
    loop.run(0.05, until=watch)
    loop.arm()
    loop.run(0.5, until=watch)  # pre-pressurise the root segments
    loop.start_task()
    loop.run(time_limit_s, until=lambda c: bool(watch and watch(c)) or (
        c is not None and c.phase in (Phase.RELEASED.value, Phase.STOPPED.value)))
    wall = time.perf_counter() - wall
    m = stack.machine
    failure: str | None = None
    if m.phase is Phase.STOPPED:
        failure = m.reason or "stopped"
    elif m.phase is not Phase.RELEASED:
        failure = f"time limit {time_limit_s:g} s reached in {m.phase.value}"
    else:
        drop = bin_drop_point(robot, r, side=m.closing_side)
        if sim.obj is None or sim.captured:
            failure = "object still in the gripper after release"
        else:
            d = float(np.hypot(*(sim.obj.xy - drop)))
            if d > BinParams.from_robot(robot).drop_radius_m:
                failure = f"object released {d * 1000:.0f} mm from the bin drop point"
    stats = loop.stats()
    return TrialResult(
        object=[x, y, r], success=failure is None, failure=failure,
        approach_s=round(m.approach_s or 0.0, 3), return_s=round(m.return_s or 0.0, 3),
        label=label, seed=seed, sim_s=round(loop.ticks * 0.01, 2), wall_s=round(wall, 3),
        ticks=loop.ticks, replans=m.replans, stalls=sim.stalls, occlusions=sim.occlusions,
        work_ms_p99=round(stats.work_ms_p99, 4),
        final_object=None if sim.obj is None else (float(sim.obj.xy[0]), float(sim.obj.xy[1])),
        side=object_side(robot, (x, y)))


@dataclasses.dataclass(frozen=True)
class TrialJob:
    """One trial of a batch, as sent to a worker process (the robot by name or path)."""

    robot_src: str
    object: tuple[float, float, float]
    seed: int
    label: str = ""
    planner: str = DEFAULT_PLANNER
    time_limit_s: float = 150.0
    sim_overrides: dict[str, Any] | None = None


def run_job(job: TrialJob) -> TrialResult:
    """:func:`run_trial` for a :class:`TrialJob` (loads the robot; picklable for process pools)."""
    robot = load(job.robot_src)
    if not isinstance(robot, SoftArm):
        raise ValueError(f"{job.robot_src} is not a soft planar arm")
    return run_trial(robot, job.object, job.seed, label=job.label, planner=job.planner,
                     time_limit_s=job.time_limit_s, sim_overrides=job.sim_overrides)


def trial_jobs(robot_src: str, objects: Sequence[tuple[str, Sequence[float]]], repeats: int,
               seed: int, *, planner: str = DEFAULT_PLANNER, time_limit_s: float = 150.0,
               sim_overrides: dict[str, Any] | None = None) -> list[TrialJob]:
    """All objects x repeats; trial ``i`` uses seed ``seed * 1000 + i`` (independent of workers)."""
    labelled = [(lab, obj) for lab, obj in objects for _ in range(repeats)]
    return [TrialJob(robot_src, (float(obj[0]), float(obj[1]), float(obj[2])), seed * 1000 + i,
                     label, planner, time_limit_s, sim_overrides)
            for i, (label, obj) in enumerate(labelled)]


MapFn = Callable[[Callable[[TrialJob], TrialResult], Sequence[TrialJob]], Iterable[TrialResult]]


def run_trials(robot_src: str, objects: Sequence[tuple[str, Sequence[float]]], repeats: int,
               seed: int, *, planner: str = DEFAULT_PLANNER, time_limit_s: float = 150.0,
               sim_overrides: dict[str, Any] | None = None,
               progress: Callable[[int, int, TrialResult], None] | None = None,
               map_fn: MapFn = map) -> list[TrialResult]:
    """All objects x repeats (seeds as :func:`trial_jobs`), results in job order.

    ``map_fn`` runs the jobs: the builtin ``map`` in this process, or a process pool's ``map``
    (e.g. ``concurrent.futures.ProcessPoolExecutor(n).map``; a threaded caller such as the
    console uses a ``spawn`` context) so the trials run in parallel outside the caller's
    interpreter. ``progress(done, total, result)`` follows each result.
    """
    jobs = trial_jobs(robot_src, objects, repeats, seed, planner=planner,
                      time_limit_s=time_limit_s, sim_overrides=sim_overrides)
    results: list[TrialResult] = []
    for result in map_fn(run_job, jobs):
        results.append(result)
        if progress:
            progress(len(results), len(jobs), result)
    return results


def summary(results: Sequence[TrialResult], wall_s: float, workers: int) -> dict[str, Any]:
    """The ``"loop"`` part of the JSON: simulated vs wall time and per-tick work."""
    sim_s = sum(r.sim_s for r in results)
    cpu_s = sum(r.wall_s for r in results)
    return {"period_s": 0.01, "clock": "simulated", "ticks": sum(r.ticks for r in results),
            "sim_s": round(sim_s, 2), "wall_s": round(wall_s, 2), "workers": workers,
            "speedup_vs_real_time": round(sim_s / wall_s, 1) if wall_s > 0 else None,
            "speedup_per_process": round(sim_s / cpu_s, 1) if cpu_s > 0 else None,
            "work_ms_p99_max": max((r.work_ms_p99 for r in results), default=0.0),
            "successes": sum(r.success for r in results), "trials": len(results),
            "sides": per_side(results)}


# -- several objects in a row (issue #17.3) ------------------------------------------------------
ROW_QUADRANT = "left"  # drawn objects lie in the left quadrant, like the paper's spots A-E


def check_row_side(robot: SoftArm, side: str) -> None:
    """Refuse a row ``side`` the robot's gripper has no finger for (ValueError with the reason):
    ``right`` and ``both`` need ``[gripper] fingers = "both"`` (:mod:`core.planning.sides`)."""
    if side not in SIDE_CHOICES:
        raise ValueError(f"side must be one of {', '.join(SIDE_CHOICES)}, got {side!r}")
    sides = robot.gripper.sides
    missing = [s for s in (("left", "right") if side == "both" else (side,)) if s not in sides]
    if missing:
        raise ValueError(f"robot '{robot.name}' has no finger closing to the {missing[0]} "
                         f"([gripper] fingers = \"{robot.gripper.fingers}\"): objects on the "
                         f"{missing[0]} need fingers = \"both\"")


def draw_row_objects(robot: SoftArm, n: int, seed: int, radius: float, side: str = "left",
                     spacing_m: float = 0.02, max_draws: int = 2000,
                     clearance: float = DEFAULT_CLEARANCE) -> list[tuple[float, float, float]]:
    """``n`` objects drawn reproducibly from ``seed`` among reachable spots on ``side``.

    Candidates are uniform over the left quadrant within the arm's reach (where the paper's
    spots lie); for a right-side object the candidate is mirrored across the base's heading
    line (:func:`core.planning.sides.mirror_xy`) into the right quadrant, where the right
    finger closes toward it. ``side``: ``left`` (the paper's), ``right``, or ``both``
    (alternating, left first). A candidate is kept when the planner (the reachability map's,
    :func:`core.planning.reachability.cell_status`, which plans on the object's side) plans a
    grasp for it from the straight arm, which is where the arm is at the start and after each
    release at the (straight) bin, and when it keeps ``spacing_m`` clear of the objects drawn
    before it and ``clearance`` clear of their plans: the approach from the straight arm of
    every object drawn before it and the straight carry from its grasp to the robot file's bin
    (held object included), so that no object is in the way of one taken before it (the
    objects not yet taken are obstacles, :mod:`core.control.row`). ValueError for a side the
    gripper has no finger for (:func:`check_row_side`).
    """
    from core.planning.reachability import map_planner
    if n < 1:
        raise ValueError(f"need at least one object, got {n}")
    check_row_side(robot, side)
    rng = np.random.default_rng([seed, 17])
    planner = map_planner(robot)
    straight = np.zeros(robot.n_segments)
    base = np.asarray(robot.base_pose[:2], dtype=float)
    out: list[tuple[float, float, float]] = []
    paths: list[_RowPath] = []
    for _ in range(max_draws):
        x, y = base + rng.uniform(0.0, robot.reach, 2) * (-1.0, 1.0)
        if np.hypot(x - base[0], y - base[1]) > robot.reach:
            continue
        if side == "right" or (side == "both" and len(out) % 2 == 1):
            x, y = mirror_xy(robot, (x, y))
        x, y = round(float(x), 4), round(float(y), 4)
        if any(np.hypot(x - ox, y - oy) < radius + r + spacing_m for ox, oy, r in out):
            continue
        if not all(p.clear_of(x, y, radius, clearance) for p in paths):
            continue
        try:
            plan = planner.plan(straight, (x, y), radius)
        except GraspRefused:
            continue
        if plan.success:
            out.append((x, y, float(radius)))
            paths.append(_RowPath.of(robot, plan, radius))
            if len(out) == n:
                return out
    raise ValueError(f"found only {len(out)} of {n} reachable, separate spots in {max_draws} draws")


@dataclasses.dataclass(frozen=True)
class _RowPath:
    """Where a drawn object's arm goes: its approach from the straight arm (waypoints) and its
    straight carry to the robot file's bin, holding it."""

    robot: SoftArm
    approach: np.ndarray     # (k, N): the straight arm, then the waypoints
    carry: np.ndarray        # (2, N): the grasp pose, the bin pose
    held: Any                # core.planning.clear_path.HeldObject

    @classmethod
    def of(cls, robot: SoftArm, plan: Any, radius: float) -> "_RowPath":
        from core.planning.clear_path import HeldObject
        side = "right" if plan.side == "right" else "left"
        chain = np.vstack([plan.kappa_meas[None], plan.kappas])
        bin_kappa = BinParams.from_robot(robot).kappa_for(side)
        return cls(robot, chain, np.vstack([plan.kappas[-1], bin_kappa]),
                   HeldObject.at_finger(robot, radius, side))

    def clear_of(self, x: float, y: float, r: float, clearance: float) -> bool:
        """Whether the approach and the carry keep ``clearance`` from a disk (certified)."""
        from core.control.carry import CARRY_PAD
        from core.planning.arm_model import ArmModel
        from core.planning.clear_path import ClearPathProblem
        from core.planning.obstacles import GripperShape, Obstacle
        model, grip = ArmModel.from_robot(self.robot), GripperShape.from_robot(self.robot)
        disk = (Obstacle("candidate", x, y, r),)
        approach = ClearPathProblem(model, grip, disk, clearance)
        if float(approach.certify(self.approach[:-1], self.approach[1:]).min()) < 0.0:
            return False
        carry = ClearPathProblem(model, grip, disk, clearance, CARRY_PAD, self.held,
                                 self.carry[0])
        return float(carry.certify(self.carry[:1], self.carry[1:]).min()) >= 0.0


@dataclasses.dataclass(frozen=True)
class RowTrialResult:
    """One row: per-object outcomes (queue order) and the run's totals.

    ``sides`` is the side of the arm each object lay on (queue order,
    :func:`core.planning.sides.object_side`); ``drops`` maps a released object's queue index to
    the finger that held it and where the simulated object lay right after the release (m).
    """

    objects: list[ObjectOutcome]
    bin: tuple[float, float] | None  # where the operator put the bin; None: the robot's [bin]
    state: str  # "done", or "stopped" (the row's time limit, a device fault)
    reason: str | None
    seed: int
    sim_s: float
    wall_s: float
    ticks: int
    stalls: int
    work_ms_p99: float
    sides: tuple[str, ...] = ()
    drops: dict[int, tuple[str, tuple[float, float]]] = dataclasses.field(default_factory=dict)

    @property
    def released(self) -> int:
        return sum(o.released for o in self.objects)

    def per_side(self) -> dict[str, dict[str, int]]:
        """``{"left": {"released": k, "objects": n}, "right": ...}`` for the sides in the row."""
        out: dict[str, dict[str, int]] = {}
        for o in self.objects:
            d = out.setdefault(self.sides[o.index], {"released": 0, "objects": 0})
            d["objects"] += 1
            d["released"] += int(o.released)
        return {s: out[s] for s in ("left", "right") if s in out}


def run_row_trial(robot: SoftArm, objects: Sequence[Sequence[float]], seed: int, *,
                  planner: str = DEFAULT_PLANNER,
                  object_time_limit_s: float = ROW_OBJECT_TIME_LIMIT_S,
                  sim_overrides: dict[str, Any] | None = None,
                  bin_xy: Sequence[float] | None = None,
                  clearance: float = DEFAULT_CLEARANCE,
                  observe: Callable[[Any], Any] | None = None) -> RowTrialResult:
    """Several objects taken to the bin one after another in one headless run.

    Like :func:`run_trial` (seeded sim, placement within +-1 mm, arm, pre-pressurise), then an
    :class:`~core.control.row.ObjectRow`: each object is put on the simulated table when its
    turn begins (the simulator holds one object at a time: a released object leaves with the
    bin, a failed one is taken off the table). An object counts as released when the machine
    released it *and* it lies within ``bin.drop_radius_m`` of the bin drop point; otherwise it
    fails with the reason (as do planner refusals, lost tracking, ... and an object not
    released within ``object_time_limit_s``), and the row goes on with the next. ``bin_xy``
    puts the bin at a point on the table (:func:`core.control.row.bin_at`; ValueError with the
    reason when it cannot be reached); by default the robot's ``[bin]``. The objects not yet
    taken are obstacles for each object's plans and carry, kept ``clearance`` (m) from
    (:mod:`core.control.row`), though the simulated table holds only the current one;
    ValueError when the bin pose is closer than that to one of them.
    """
    row_objects = [RowObject(*(float(v) for v in obj)) for obj in objects]
    where = None if bin_xy is None else (float(bin_xy[0]), float(bin_xy[1]))
    bin_params = None if where is None else bin_at(robot, *where)
    rng = np.random.default_rng([seed, 7])
    plan_fn: Callable[..., Any] = resolve(planner)
    sim = SoftArmSim(robot, seed=seed)
    if sim_overrides:
        sim.p = sim.p.replace(**sim_overrides)
    stack = ControlStack(robot, 0.01, immediate(
        lambda req: plan_request(plan_fn, robot, req)))
    stack.set_obstacles((), clearance)  # the row adds the objects not yet taken
    loop = SimLoop(sim, stack, 0.01)
    drop_radius = BinParams.from_robot(robot).drop_radius_m
    drops: dict[int, tuple[str, tuple[float, float]]] = {}

    def place(obj: RowObject) -> None:
        sim.place_object(obj.x + rng.uniform(-PLACEMENT_TOLERANCE_M, PLACEMENT_TOLERANCE_M),
                         obj.y + rng.uniform(-PLACEMENT_TOLERANCE_M, PLACEMENT_TOLERANCE_M), obj.r)

    def in_bin(obj: RowObject) -> str | None:
        if sim.obj is None or sim.captured:
            return "object still in the gripper after release"
        # Held by the finger that closed on it: its drop point is on that side of the gripper.
        side = stack.machine.closing_side
        assert row.current is not None
        drops[row.current] = (side, (float(sim.obj.xy[0]), float(sim.obj.xy[1])))
        d = float(np.hypot(*(sim.obj.xy - bin_drop_point(robot, obj.r, bin_params, side))))
        return None if d <= drop_radius else f"object released {d * 1000:.0f} mm from the bin drop point"

    wall = time.perf_counter()
    loop.run(0.05)
    loop.arm()
    loop.run(0.5)  # pre-pressurise the root segments
    row = ObjectRow(row_objects, bin_params, object_time_limit_s, check_release=in_bin)
    run_row(loop, row, place, object_time_limit_s * len(row_objects) + 1.0, observe=observe)
    wall = time.perf_counter() - wall
    return RowTrialResult(list(row.outcomes), where, row.state, row.reason, seed,
                          round(loop.ticks * 0.01, 2), round(wall, 3), loop.ticks, sim.stalls,
                          round(loop.stats().work_ms_p99, 4),
                          tuple(object_side(robot, (o.x, o.y)) for o in row_objects), drops)


def row_json(result: RowTrialResult) -> dict[str, Any]:
    """The ``--json`` form of a row: per-object results (SI units) and the totals."""
    def num(v: float | None) -> float | None:
        return None if v is None else round(v, 3)
    def drop(i: int) -> dict[str, Any]:
        finger, xy = result.drops.get(i, (None, None))
        return {"finger": finger, "final_object": None if xy is None else list(xy)}
    return {"row": [{"object": [o.object.x, o.object.y, o.object.r], "status": o.status,
                     "reason": o.reason, "started_s": num(o.started_s), "ended_s": num(o.ended_s),
                     "approach_s": num(o.approach_s), "return_s": num(o.return_s),
                     "replans": o.replans, "side": result.sides[o.index], **drop(o.index)}
                    for o in result.objects],
            "bin": None if result.bin is None else list(result.bin),
            "released": result.released, "objects": len(result.objects),
            "sides": result.per_side(), "state": result.state,
            "reason": result.reason, "seed": result.seed, "sim_s": result.sim_s,
            "wall_s": result.wall_s}
