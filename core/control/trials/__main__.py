"""``python -m core.control.trials``: the paper's grasp-and-place experiment from the command line.

``python -m core.control.trials [--object X Y R ...] [--repeats N] [--seed S] [--json]
[--workers N] [--robot NAME|PATH] [--planner MODULE:FUNCTION] [--time-limit S] [--sim KEY=VALUE]
[--side left|right|both] [--objects-in-a-row N [--bin X Y]]``

Without ``--object`` the five spots A-E of :func:`core.control.trials.paper_locations` are used,
x 5 repeats, with the paper's 3.3 cm object. ``--side right`` runs their mirror images across
the arm's base line instead (A'-E', the Fig. 7 experiment mirrored), ``--side both`` the spots
and then their mirror images (also for ``--object``); the table and the JSON report the
successes per side. Trials run in ``--workers`` parallel processes
(a pool owned here; ``--workers 0``: in this process). Prints a table, or with ``--json`` one
object ``{"trials": [...], "loop": {...}}`` (``loop.sides``: ``{"left": {"successes": k,
"trials": n}, "right": ...}``).

``--objects-in-a-row N`` instead takes N objects to the bin one after another in one run
(:func:`core.control.trials.run_row_trial`): the N ``--object`` given, or without ``--object``
N drawn from ``--seed`` among reachable spots (paper's object radius) on ``--side``: left (the
default), right (the right finger's quadrant), or both (alternating, left first); a side the
robot file's gripper has no finger for is refused. ``--time-limit`` is then per object
(default 300 s: an object far from the bin, carried around the others, can take ~150 s);
``--bin X Y`` puts the bin at that point of the table (m) instead of the robot file's bin
configuration. The objects not yet taken are obstacles for each object's plans and carry,
kept ``--clearance`` (m, default 0.01) from. Prints one row per object (its side, released /
failed and why), "k/N released" and the released count per side, or with ``--json`` one
object ``{"row": [...], "released": k, "objects": N, "sides": {"left": {"released": k, "objects": n}, ...}, ...}``
(each row entry with its ``side``, the ``finger`` that held it and the simulated
``final_object`` position after the release).
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import functools
import json
import math
import sys
import time
from pathlib import Path
from typing import Any, Callable, Sequence

from core.control.params import SimParams
from core.control.planner_spec import DEFAULT_PLANNER
from core.control.row import bin_at
from core.control.trials import (ROW_OBJECT_TIME_LIMIT_S, SIDE_CHOICES, RowTrialResult,
                                 TrialResult, draw_row_objects, paper_locations, per_side,
                                 row_json, run_row_trial, run_trials, sided_objects, summary)
from core.planning.obstacles import DEFAULT_CLEARANCE, check_clearance
from core.robots import SoftArm, load
from core.units import fmt_mm


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


def format_table(results: Sequence[TrialResult]) -> str:
    """Fixed-width results table (one row per trial, then per-spot success counts).

    Lengths in mm and times in s, the unit in each column's header (``--json`` and ``--csv``
    stay SI).
    """
    lines = [f"{'#':>3} {'spot':<4} {'x (mm)':>7} {'y (mm)':>7} {'r (mm)':>6} {'ok':<3} "
             f"{'approach (s)':>12} {'return (s)':>10} {'replans':>7} {'stalls':>6}  failure"]
    for i, r in enumerate(results, 1):
        x, y, rad = r.object
        lines.append(f"{i:>3} {r.label:<4} {fmt_mm(x):>7} {fmt_mm(y):>7} {fmt_mm(rad):>6} "
                     f"{'yes' if r.success else 'NO':<3} {r.approach_s:>12.1f} "
                     f"{r.return_s:>10.1f} {r.replans:>7d} {r.stalls:>6d}  {r.failure or ''}")
    by: dict[str, list[bool]] = {}
    for r in results:
        by.setdefault(r.label, []).append(r.success)
    lines.append("per spot: " + ", ".join(f"{k or '-'} {sum(v)}/{len(v)}" for k, v in by.items()))
    lines.append("per side: " + ", ".join(f"{side} {d['successes']}/{d['trials']}"
                                           for side, d in per_side(results).items()))
    lines.append(f"total: {sum(r.success for r in results)}/{len(results)} successes")
    return "\n".join(lines)


def format_row_table(result: RowTrialResult) -> str:
    """One row per object of a row run (lengths in mm, times in s), then "k/N released"."""
    lines = [(f"{'#':>3} {'x (mm)':>7} {'y (mm)':>7} {'r (mm)':>6} {'status':<8} "
              f"{'approach (s)':>12} {'return (s)':>10} {'replans':>7} {'side':<5}  reason")]
    for o in result.objects:
        times = (f"{o.approach_s:>12.1f}" if o.approach_s is not None else f"{'-':>12}",
                 f"{o.return_s:>10.1f}" if o.return_s is not None else f"{'-':>10}")
        lines.append(f"{o.index + 1:>3} {fmt_mm(o.object.x):>7} {fmt_mm(o.object.y):>7} "
                     f"{fmt_mm(o.object.r):>6} {o.status:<8} {times[0]} {times[1]} "
                     f"{o.replans:>7d} {result.sides[o.index]:<5}  {o.reason or ''}")
    if result.bin is not None:
        lines.append(f"bin at ({fmt_mm(result.bin[0])}, {fmt_mm(result.bin[1])}) mm")
    lines.append(f"{result.released}/{len(result.objects)} released"
                 + (f" (row stopped: {result.reason})" if result.state == "stopped" else ""))
    lines.append("per side: " + ", ".join(f"{side} {d['released']}/{d['objects']} released"
                                           for side, d in result.per_side().items()))
    return "\n".join(lines)


def run_row_cli(a: argparse.Namespace, ap: argparse.ArgumentParser, robot: SoftArm,
                overrides: dict[str, Any]) -> int:
    """``--objects-in-a-row N``: one row run in this process, table or JSON."""
    n = a.objects_in_a_row
    if a.repeats is not None or a.record is not None or a.csv is not None:
        ap.error("--objects-in-a-row runs one row: --repeats, --record and --csv do not apply")
    bin_xy = None
    if a.bin is not None:
        bin_xy = tuple(a.bin)
        try:
            bin_at(robot, *bin_xy)
        except ValueError as exc:
            ap.error(f"--bin {a.bin[0]} {a.bin[1]}: {exc}")
    if a.object:
        if a.side is not None:
            ap.error("--side draws the row's objects on that side; with --object each object is "
                     "grasped on the side where it lies")
        if len(a.object) != n:
            ap.error(f"--objects-in-a-row {n} with {len(a.object)} --object: give {n} objects, "
                     f"or none to draw {n} from --seed")
        objects = [tuple(o) for o in a.object]
    else:
        try:
            objects = draw_row_objects(robot, n, a.seed, robot.capture.nominal_object_radius,
                                       side=a.side or "left")
        except ValueError as exc:
            ap.error(f"--objects-in-a-row {n} --side {a.side or 'left'}: {exc}")
    try:
        result = run_row_trial(robot, objects, a.seed, planner=a.planner, bin_xy=bin_xy,
                               object_time_limit_s=a.time_limit, clearance=a.clearance,
                               sim_overrides=overrides or None)
    except ValueError as exc:  # a bin pose too close to an object still on the table
        ap.error(f"--objects-in-a-row {n}: {exc}")
    if a.json:
        print(json.dumps(row_json(result)))
    else:
        print(format_row_table(result))
        print(f"simulated {result.sim_s} s in {result.wall_s} s wall")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m core.control.trials", description=__doc__.split("\n")[0])
    ap.add_argument("--object", nargs=3, type=float, action="append", metavar=("X", "Y", "R"),
                    help="object centre and radius (m); repeatable. Default: the paper's A-E")
    ap.add_argument("--repeats", type=int, default=None, help="trials per object (default 5)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", action="store_true", help="print JSON instead of the table")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--robot", default="soft-arm")
    ap.add_argument("--planner", default=DEFAULT_PLANNER, help="module:function (default %(default)s)")
    ap.add_argument("--time-limit", type=float, default=None,
                    help="simulated s per trial (default 150), per object with "
                         "--objects-in-a-row (default 300)")
    ap.add_argument("--sim", action="append", default=[], metavar="KEY=VALUE",
                    help="override a [sim] parameter, e.g. stall_rate_hz=0.5 or mocap.noise_m=5e-4")
    ap.add_argument("--record", type=Path, default=None, metavar="PATH.mcap",
                    help="also record the trials (arm, object, phases) as MCAP")
    ap.add_argument("--csv", type=Path, default=None, metavar="PATH.csv",
                    help="also write one CSV row per trial (units in the header)")
    ap.add_argument("--side", choices=SIDE_CHOICES, default=None,
                    help="left (default): the spots as given (the paper's experiment); right: "
                         "their mirror images across the arm's base line; both: each, then its "
                         "mirror image. With --objects-in-a-row: the side the row's objects are "
                         "drawn on (both: alternating)")
    ap.add_argument("--objects-in-a-row", type=int, default=None, metavar="N",
                    help="take N objects to the bin one after another in one run: the N "
                         "--object given, or N drawn from --seed among reachable spots")
    ap.add_argument("--bin", nargs=2, type=float, default=None, metavar=("X", "Y"),
                    help="with --objects-in-a-row: put the bin at this point of the table (m)")
    ap.add_argument("--clearance", type=float, default=None, metavar="M",
                    help="with --objects-in-a-row: what each object's plans keep from the "
                         f"objects not yet taken (m, default {DEFAULT_CLEARANCE:g})")
    a = ap.parse_args(argv)
    if a.record is not None and (a.record.suffix != ".mcap" or a.record.exists()):
        ap.error(f"--record {a.record}: need a new file ending in .mcap")
    try:
        overrides = parse_overrides(a.sim)
        if overrides:
            SimParams.from_robot(load(a.robot)).replace(**overrides)  # validate names now
    except (ValueError, TypeError) as exc:
        ap.error(str(exc))
    if a.repeats is not None and a.repeats < 1:
        ap.error("--repeats must be >= 1")
    if a.objects_in_a_row is not None and a.objects_in_a_row < 1:
        ap.error("--objects-in-a-row must be >= 1")
    if a.time_limit is None:
        a.time_limit = ROW_OBJECT_TIME_LIMIT_S if a.objects_in_a_row is not None else 150.0
    if not (math.isfinite(a.time_limit) and a.time_limit > 0):
        ap.error(f"--time-limit {a.time_limit}: need a number of seconds > 0")
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
    if a.objects_in_a_row is not None:
        if a.clearance is None:
            a.clearance = DEFAULT_CLEARANCE
        try:
            check_clearance(a.clearance)
        except ValueError as exc:
            ap.error(f"--clearance {a.clearance}: {exc}")
        return run_row_cli(a, ap, robot, overrides)
    if a.bin is not None:
        ap.error("--bin applies to --objects-in-a-row only")
    if a.clearance is not None:
        ap.error("--clearance applies to --objects-in-a-row only (a trial has one object)")
    repeats = 5 if a.repeats is None else a.repeats
    if a.object:
        objects = [(f"#{i + 1}", o) for i, o in enumerate(a.object)]
    else:
        r0 = robot.capture.nominal_object_radius
        objects = [(k, (x, y, r0)) for k, (x, y) in paper_locations().items()]
    objects = sided_objects(robot, objects, a.side or "left")
    wall = time.perf_counter()
    from core.labdata.progress import trial_progress  # a bar on a terminal, nothing when piped
    with trial_progress(len(objects) * repeats) as progress:
        batch = dict(planner=a.planner, time_limit_s=a.time_limit,
                     sim_overrides=overrides or None, progress=progress)
        run: Callable[..., Any] = run_trials
        if a.record is not None:
            from core.labdata.trial_recording import record_trials
            run = functools.partial(record_trials, a.record)
        if a.workers >= 1:
            with cf.ProcessPoolExecutor(a.workers) as pool:
                results = run(a.robot, objects, repeats, a.seed, map_fn=pool.map, **batch)
        else:
            results = run(a.robot, objects, repeats, a.seed, **batch)
    if a.csv is not None:
        from core.labdata.results_csv import write_trials_csv
        write_trials_csv(a.csv, results)
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
