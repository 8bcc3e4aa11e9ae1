"""Headless grasp-and-place trials on the simulated arm, reproducing the paper's experiment (§5.2).

``python -m core.control.trials [--object X Y R ...] [--repeats N] [--seed S] [--json]``

Each trial builds a seeded :class:`~core.control.sim.SoftArmSim`, places the object (the user's
placement is uniform within +-1 mm of the spot, as in the paper), arms the controller and runs
the full grasp-and-place through the loop runner (``hw_bridge.loop``) on its simulated clock,
until ``released``, ``stopped`` or a time limit. Success: released, and the object put down within
``bin.drop_radius_m`` of the bin drop point (where the object sits when the gripper is at the
bin). Without ``--object`` the five spots A-E of :func:`paper_locations` are used, x 5 repeats,
with the paper's 3.3 cm object. Trials run in parallel processes (``--workers``).

This module is the CLI around the pure pieces: it is the one place in ``core.control`` that
prints, and it imports the loop runner from ``hw_bridge`` lazily.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import dataclasses
import json
import math
import sys
import time
from typing import Any, Callable, Sequence

import numpy as np

from core.control.grasp_place import Phase, immediate
from core.control.params import BinParams
from core.control.sim import SoftArmSim
from core.control.stack import ControlStack
from core.kinematics.planar import forward_kinematics, point_in_frame
from core.robots import SoftArm, load

DEFAULT_PLANNER = "core.planning.grasp:plan_grasp"
PLACEMENT_TOLERANCE_M = 0.001  # the paper: user placement within +-1 mm


def paper_locations() -> dict[str, tuple[float, float]]:
    """Spots A-E across the left quadrant (m), spread over the reachable workspace like Fig. 7.

    From near the base's side to far up the workspace: A low and far left, B mid-left, C close
    in, D up and left, E high near the arm's straight line. All are at least a gripper length
    away from the straight arm (so the approach is not trivial) and feasible for the planner.
    """
    return {"A": (-0.26, 0.10), "B": (-0.22, 0.20), "C": (-0.13, 0.17),
            "D": (-0.16, 0.28), "E": (-0.08, 0.33)}


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


def bin_drop_point(robot: SoftArm, radius: float) -> np.ndarray:
    """Where the grasped object sits when the arm is at the bin configuration."""
    b = BinParams.from_robot(robot)
    tip = forward_kinematics(b.kappa, robot.lengths, robot.base_pose)[-1]
    return point_in_frame(tip, (robot.gripper.w_off_along, 2 * robot.gripper.g_off + radius))


def run_trial(robot: SoftArm, obj: Sequence[float], seed: int, *, label: str = "",
              planner: str = DEFAULT_PLANNER, time_limit_s: float = 150.0,
              sim_overrides: dict[str, Any] | None = None) -> TrialResult:
    """One headless grasp-and-place trial on the simulated clock."""
    from hw_bridge.loop import LoopRunner, SimClock, SimDevice, resolve

    x, y, r = (float(v) for v in obj)
    rng = np.random.default_rng([seed, 7])
    plan_fn: Callable[..., Any] = resolve(planner)
    sim = SoftArmSim(robot, seed=seed)
    if sim_overrides:
        sim.p = sim.p.replace(**sim_overrides)
    sim.place_object(x + rng.uniform(-PLACEMENT_TOLERANCE_M, PLACEMENT_TOLERANCE_M),
                     y + rng.uniform(-PLACEMENT_TOLERANCE_M, PLACEMENT_TOLERANCE_M), r)
    stack = ControlStack(robot, 0.01, immediate(
        lambda req: plan_fn(robot, req.kappa, req.center, req.radius)))
    runner = LoopRunner(SimDevice(sim), stack, 0.01, clock_ns=SimClock())
    wall = time.perf_counter()
    runner.run_sim(0.05)
    runner.arm()
    runner.run_sim(0.5)  # pre-pressurise the root segments
    runner.start_task()
    runner.run_sim(time_limit_s, until=lambda s: s.control is not None
                   and s.control.phase in (Phase.RELEASED.value, Phase.STOPPED.value))
    wall = time.perf_counter() - wall
    m = stack.machine
    failure: str | None = None
    if m.phase is Phase.STOPPED:
        failure = m.reason or "stopped"
    elif m.phase is not Phase.RELEASED:
        failure = f"time limit {time_limit_s:g} s reached in {m.phase.value}"
    else:
        drop = bin_drop_point(robot, r)
        if sim.obj is None or sim.captured:
            failure = "object still in the gripper after release"
        else:
            d = float(np.hypot(*(sim.obj.xy - drop)))
            if d > BinParams.from_robot(robot).drop_radius_m:
                failure = f"object released {d * 1000:.0f} mm from the bin drop point"
    stats = runner.stats()
    return TrialResult(
        object=[x, y, r], success=failure is None, failure=failure,
        approach_s=round(m.approach_s or 0.0, 3), return_s=round(m.return_s or 0.0, 3),
        label=label, seed=seed, sim_s=round(runner.ticks * 0.01, 2), wall_s=round(wall, 3),
        ticks=runner.ticks, replans=m.replans, stalls=sim.stalls, occlusions=sim.occlusions,
        work_ms_p99=round(stats.work_ms_p99, 4),
        final_object=None if sim.obj is None else (float(sim.obj.xy[0]), float(sim.obj.xy[1])))


def _run_one(args: tuple) -> TrialResult:
    robot_src, obj, seed, label, planner, limit, overrides = args
    robot = load(robot_src)
    assert isinstance(robot, SoftArm)
    return run_trial(robot, obj, seed, label=label, planner=planner, time_limit_s=limit,
                     sim_overrides=overrides)


def parse_overrides(items: Sequence[str]) -> dict[str, Any]:
    """``["stall_rate_hz=0.5", "mocap.noise_m=0.0005"]`` -> SimParams.replace keyword dict."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        try:
            num = float(value)
        except ValueError:
            num = math.nan
        if not sep or not math.isfinite(num):
            raise ValueError(f"--sim {item!r}: expected KEY=NUMBER (e.g. stall_rate_hz=0.5)")
        group, _, field = key.rpartition(".")
        if group:
            out.setdefault(group, {})[field] = num
        else:
            out[key] = num
    return out


def run_trials(robot_src: str, objects: Sequence[tuple[str, Sequence[float]]], repeats: int,
               seed: int, *, workers: int = 2, planner: str = DEFAULT_PLANNER,
               time_limit_s: float = 150.0, sim_overrides: dict[str, Any] | None = None,
               progress: Callable[[int, int, TrialResult], None] | None = None,
               mp_context: str | None = None,
               initializer: Callable[[], Any] | None = None) -> list[TrialResult]:
    """All objects x repeats; trial ``i`` uses seed ``seed * 1000 + i`` (independent of workers).

    ``workers >= 1`` runs the trials in that many worker processes (so a caller such as the
    console keeps its own interpreter free; a threaded caller should pass
    ``mp_context="spawn"``); ``workers <= 0`` runs them in this process. ``initializer`` runs
    in each worker first (the console's makes a worker end with it).
    """
    jobs = [(robot_src, list(map(float, obj)), seed * 1000 + i, label, planner, time_limit_s,
             sim_overrides)
            for i, (label, obj) in enumerate((lab, o) for lab, o in objects for _ in range(repeats))]
    results: list[TrialResult | None] = [None] * len(jobs)
    if workers <= 0:
        for i, job in enumerate(jobs):
            results[i] = _run_one(job)
            if progress:
                progress(i + 1, len(jobs), results[i])
    else:
        import multiprocessing
        ctx = multiprocessing.get_context(mp_context) if mp_context else None
        with cf.ProcessPoolExecutor(workers, mp_context=ctx, initializer=initializer) as pool:
            futs = {pool.submit(_run_one, job): i for i, job in enumerate(jobs)}
            for k, fut in enumerate(cf.as_completed(futs)):
                results[futs[fut]] = fut.result()
                if progress:
                    progress(k + 1, len(jobs), results[futs[fut]])
    return [r for r in results if r is not None]


def summary(results: Sequence[TrialResult], wall_s: float, workers: int) -> dict[str, Any]:
    """The ``"loop"`` part of the JSON: simulated vs wall time and per-tick work."""
    sim_s = sum(r.sim_s for r in results)
    cpu_s = sum(r.wall_s for r in results)
    return {"period_s": 0.01, "clock": "simulated", "ticks": sum(r.ticks for r in results),
            "sim_s": round(sim_s, 2), "wall_s": round(wall_s, 2), "workers": workers,
            "speedup_vs_real_time": round(sim_s / wall_s, 1) if wall_s > 0 else None,
            "speedup_per_process": round(sim_s / cpu_s, 1) if cpu_s > 0 else None,
            "work_ms_p99_max": max((r.work_ms_p99 for r in results), default=0.0),
            "successes": sum(r.success for r in results), "trials": len(results)}


def format_table(results: Sequence[TrialResult]) -> str:
    """Fixed-width results table (one row per trial, then per-spot success counts)."""
    lines = [f"{'#':>3} {'spot':<4} {'x':>7} {'y':>7} {'r':>6} {'ok':<3} {'approach_s':>10} "
             f"{'return_s':>8} {'replans':>7} {'stalls':>6}  failure"]
    for i, r in enumerate(results, 1):
        x, y, rad = r.object
        lines.append(f"{i:>3} {r.label:<4} {x:>7.3f} {y:>7.3f} {rad:>6.4f} "
                     f"{'yes' if r.success else 'NO':<3} {r.approach_s:>10.1f} {r.return_s:>8.1f} "
                     f"{r.replans:>7d} {r.stalls:>6d}  {r.failure or ''}")
    by: dict[str, list[bool]] = {}
    for r in results:
        by.setdefault(r.label, []).append(r.success)
    lines.append("per spot: " + ", ".join(f"{k or '-'} {sum(v)}/{len(v)}" for k, v in by.items()))
    lines.append(f"total: {sum(r.success for r in results)}/{len(results)} successes")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m core.control.trials", description=__doc__.split("\n")[0])
    ap.add_argument("--object", nargs=3, type=float, action="append", metavar=("X", "Y", "R"),
                    help="object centre and radius (m); repeatable. Default: the paper's A-E")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", action="store_true", help="print JSON instead of the table")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--robot", default="soft-arm")
    ap.add_argument("--planner", default=DEFAULT_PLANNER, help="module:function (default %(default)s)")
    ap.add_argument("--time-limit", type=float, default=150.0, help="simulated s per trial")
    ap.add_argument("--sim", action="append", default=[], metavar="KEY=VALUE",
                    help="override a [sim] parameter, e.g. stall_rate_hz=0.5 or mocap.noise_m=5e-4")
    a = ap.parse_args(argv)
    try:
        overrides = parse_overrides(a.sim)
        if overrides:
            from core.control.params import SimParams
            SimParams.from_robot(load(a.robot)).replace(**overrides)  # validate names now
    except (ValueError, TypeError) as exc:
        ap.error(str(exc))
    if a.repeats < 1:
        ap.error("--repeats must be >= 1")
    try:
        robot = load(a.robot)
    except ValueError as exc:
        ap.error(str(exc))
    if not isinstance(robot, SoftArm):
        ap.error(f"{a.robot} is not a soft planar arm")
    if a.object:
        for x, y, r in a.object:
            if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(r)) or r <= 0:
                ap.error(f"--object {x} {y} {r}: need finite X Y and R > 0")
        objects = [(f"#{i + 1}", o) for i, o in enumerate(a.object)]
    else:
        r0 = robot.capture.nominal_object_radius
        objects = [(k, (x, y, r0)) for k, (x, y) in paper_locations().items()]
    wall = time.perf_counter()
    progress = None if a.json else (lambda k, n, r: print(
        f"  trial {k}/{n}: {r.label} {'ok' if r.success else 'FAILED'}", file=sys.stderr, flush=True))
    results = run_trials(a.robot, objects, a.repeats, a.seed, workers=a.workers,
                         planner=a.planner, time_limit_s=a.time_limit,
                         sim_overrides=overrides or None, progress=progress)
    loop = summary(results, time.perf_counter() - wall, a.workers)
    if a.json:
        keys = ("object", "success", "failure", "approach_s", "return_s")
        print(json.dumps({"trials": [{k: getattr(r, k) for k in keys} for r in results],
                          "loop": loop}))
    else:
        print(format_table(results))
        print(f"simulated {loop['sim_s']} s in {loop['wall_s']} s wall with {a.workers} workers: "
              f"{loop['speedup_vs_real_time']}x real time ({loop['speedup_per_process']}x per process)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
