"""Grasp planner (Algorithm 1) speed: this planner against the tools a user would reach for.

In ONE run, times a full plan by: this planner as the console plans (core.planning.sides
SidedPlanner, which runs core.planning.grasp's Algorithm 1 for the finger on the object's side,
including its feasibility checks and the clearance certificate the baselines do not compute),
CasADi's ``sqpmethod`` with exact AD derivatives, CasADi's IPOPT, and a literal port of
Algorithm 1 (scipy SLSQP with finite-difference gradients, as MATLAB's fmincon would run it), on
these object sets:

* ``fixed grid``: a grid over the left quadrant, three sizes (2, 3.3, 5 cm diameter), arm
  straight; every method.
* ``random left`` / ``random right``: a fresh random set drawn each run (the seed is printed;
  ``--seed S`` repeats a run) uniformly over each quadrant within reach, 2-5 cm diameter, arm
  straight (as the paper's experiment starts); this planner and CasADi sqpmethod. The default
  robot file has the stacked finger pair (``[gripper] fingers = "both"``, paper Sec. 5.3
  option 1), so a right-quadrant object is grasped with the RIGHT finger: the request is
  mirrored about the base's heading line, planned by Algorithm 1 unchanged and mirrored back.
  CasADi solves that same NLP (benchmarks/planner_baselines.py SidedCasadiPlanner: the mirrored
  object on the same formulation, same tolerances, same start, its curvatures mirrored back).
  An object counts as graspable when either method returns a plan that keeps the arm body clear
  of it (at the waypoints and along the straight lines in kappa between them); the random sets
  draw graspable objects, and the others are counted and listed as skipped.

These three sets are the goal sets. One more set is printed for information only, outside the
goal line: ``random right, left finger only``, the paper's single finger (``fingers = "left"``)
planning right-quadrant objects as an S-curl, from the straight arm or (``--right-start
curled``) from the extreme curvature into the right quadrant (Sec. 5.3 option 3). It is not
what the console plans with the default robot file, and it is not a fair race: the S-curl sweeps
the arm through most objects, which this planner reports as a clearance failure after searching
for a clear path, while CasADi (which checks no clearance) mostly fails to converge there
(``--no-single-finger`` skips the set).

Objects this planner refuses (out of reach, on the base) are skipped and counted. Methods are
interleaved object by object (this planner and CasADi sqpmethod run by run) so machine load hits
them alike; per object each method's time is the best of several runs (background load only
adds time), measured by default as CPU time of the planning thread, which every method runs in
(``--clock wall`` for wall-clock time; on a shared machine CPU time is far less noisy). Per set
it prints both medians side by side and their ratio over the objects both solve (objects the
baseline fails are listed separately), success rates, the finger each plan used, whether the
final configurations agree with CasADi's (max |d kappa| < 1e-3), and the goals: >= 2x CasADi
sqpmethod by median on every goal set at 100 % success, and >= 10x the literal port on every
fixed-grid object.

With numba installed this planner's plain Newton iterations run compiled
(:mod:`core.planning.solver_jit`; compiled in the untimed warm-up if needed);
``GRASP_SOLVER_JIT=0`` times the pure-Python path.

Usage: python benchmarks/bench_planner.py [--repeats 5] [--quick] [--random 30] [--seed S]
       [--clock cpu|wall] [--right-start straight|curled] [--no-single-finger] [--no-ipopt]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from core import robots  # noqa: E402
from core.planning.arm_model import ArmModel  # noqa: E402
from core.planning.grasp import GraspPlanner, GraspRefused  # noqa: E402
from core.planning.sides import SidedPlanner  # noqa: E402
from planner_baselines import CasadiPlanner, SidedCasadiPlanner, literal_port  # noqa: E402

# The planner's compiled Newton kernel (core.planning.solver_jit) when numba is installed:
# compiled here during the untimed warm-up if it is not in numba's disk cache yet.
# GRASP_SOLVER_JIT=0 times the pure-Python path.
os.environ.setdefault("GRASP_SOLVER_JIT", "1")

GOAL_VS_CASADI = 2.0
GOAL_VS_LITERAL = 10.0
QUADRANT_X = (0.02, 0.50)       # |x| range of the random objects (m)
QUADRANT_Y = (0.02, 0.50)       # y range (m)
SIZES = (0.010, 0.025)          # object radius range (m): 2-5 cm diameter


@dataclasses.dataclass
class ObjectSet:
    """One benchmark set: its name, start configuration, objects (x, y, r) and the planners
    timed on it (this planner, CasADi sqpmethod and, for ``all_methods``, CasADi IPOPT)."""

    name: str
    start: np.ndarray
    objects: list[tuple[float, float, float]]
    ours: GraspPlanner | SidedPlanner
    cas: CasadiPlanner | SidedCasadiPlanner
    drawn: int = 0              # random sets: objects drawn, including those refused
    all_methods: bool = False
    in_goal: bool = True        # False: printed for information, outside the goal line


def grid_objects(quick: bool) -> list[tuple[float, float, float]]:
    """Fixed object set: a grid over the left quadrant, three sizes (2, 3.3, 5 cm diameter)."""
    xs = np.arange(-0.30, -0.049, 0.05 if not quick else 0.10)
    ys = np.arange(0.05, 0.351, 0.05 if not quick else 0.10)
    sizes = (0.010, 0.0165, 0.025)
    return [(round(float(x), 3), round(float(y), 3), r) for r in sizes for x in xs for y in ys]



def random_set(name: str, planner: GraspPlanner | SidedPlanner,
               cas: CasadiPlanner | SidedCasadiPlanner, start: np.ndarray, side: float,
               count: int, rng: np.random.Generator, in_goal: bool = True
               ) -> tuple[ObjectSet, dict]:
    """``count`` graspable objects uniform over one quadrant (``side`` -1 left, +1 right), and
    the skipped ones by reason (refused by this planner's feasibility check, or graspable by
    neither method: no clear plan found)."""
    objs, skipped, drawn = [], {"refused": [], "no clear plan": []}, 0
    model = planner.model
    while len(objs) < count and drawn < 100 * count:
        drawn += 1
        o = (side * float(rng.uniform(*QUADRANT_X)), float(rng.uniform(*QUADRANT_Y)),
             float(rng.uniform(*SIZES)))
        try:
            p = planner.plan(start, o[:2], o[2])
        except GraspRefused as exc:
            skipped["refused"].append((o, exc.reason))
            continue
        if not p.success:
            pc = cas.plan(start, o[:2], o[2])
            if not pc.success or sweeps_into_object(model, start, pc.kappas, o):
                skipped["no clear plan"].append((o, p.failures[0].reason))
                continue
        objs.append(o)
    return ObjectSet(name, start, objs, planner, cas, drawn, in_goal=in_goal), skipped


CLOCKS = {"cpu": time.thread_time, "wall": time.perf_counter}


def timed(fn, repeats: int, clock=time.thread_time):
    """Best of ``repeats`` times in ms (the usual estimator under background load, as in
    timeit: interference only ever adds time), and the last result."""
    times, out = [], None
    for _ in range(repeats):
        t = clock()
        out = fn()
        times.append(clock() - t)
    return float(np.min(times)) * 1e3, out


def timed_pair(fa, fb, repeats: int, clock=time.thread_time):
    """Like :func:`timed` for two methods, alternating them run by run (a, b, a, b, ...) so that
    a burst of background load hits both alike."""
    ta, tb, ra, rb = [], [], None, None
    for _ in range(repeats):
        t = clock()
        ra = fa()
        ta.append(clock() - t)
        t = clock()
        rb = fb()
        tb.append(clock() - t)
    return float(np.min(ta)) * 1e3, ra, float(np.min(tb)) * 1e3, rb


def sweeps_into_object(model: ArmModel, start: np.ndarray, kappas: np.ndarray, obj) -> bool:
    """Whether the arm body cuts into the object at a waypoint or on a straight line in kappa
    between them (64 samples per line): what a plan without clearance checks can return."""
    chain = np.vstack([start, kappas])
    tau = np.linspace(0.0, 1.0, 65)[:, None]
    lines = chain[:-1, None, :] + tau * (chain[1:] - chain[:-1])[:, None, :]
    return bool(model.body_clearance(lines, complex(obj[0], obj[1]), obj[2]).min() < 0.0)


def run_set(s: ObjectSet, robot, ipo, repeats: int, clock):
    """Time every method on every object of ``s``; returns per-method times, successes, per
    object both solve (object, max |d kappa| of the final configurations, whether CasADi's plan
    sweeps into the object, each final configuration's distance from the start), how many CasADi plans sweep into their object and the finger each
    of this planner's plans used."""
    names = ["this planner", "CasADi sqpmethod (exact AD)"]
    if s.all_methods:
        names += ["CasADi ipopt (exact AD)", "literal port (SLSQP, FD grads)"]
    ms = {k: [] for k in names}
    ok = {k: [] for k in names}
    same, swept, fingers = [], 0, []
    km, ours, cas = s.start, s.ours, s.cas
    for x, y, r in s.objects:
        t0, p, t1, pc = timed_pair(lambda: ours.plan(km, (x, y), r),
                                   lambda: cas.plan(km, (x, y), r), repeats, clock)
        ms[names[0]].append(t0)
        ok[names[0]].append(p.success)
        fingers.append(p.side)
        ms[names[1]].append(t1)
        ok[names[1]].append(pc.success)
        cas_sweeps = pc.success and sweeps_into_object(ours.model, km, pc.kappas, (x, y, r))
        swept += cas_sweeps
        if s.all_methods:
            if ipo is not None:
                t2, pi = timed(lambda: ipo.plan(km, (x, y), r), max(1, repeats // 2), clock)
                ms[names[2]].append(t2)
                ok[names[2]].append(pi.success)
            t3, pl = timed(lambda: literal_port(robot, km, (x, y), r), 2, clock)
            ms[names[3]].append(t3)
            ok[names[3]].append(pl.success)
        alg = ~p.inserted
        if p.success and pc.success and alg.sum() == len(pc.kappas):
            same.append(((x, y, r), float(np.abs(p.kappas[alg][-1] - pc.kappas[-1]).max()),
                         bool(cas_sweeps), float(np.linalg.norm(p.kappas[alg][-1] - km)),
                         float(np.linalg.norm(pc.kappas[-1] - km))))
    return names, ms, ok, same, swept, fingers


def report_set(s: ObjectSet, names, ms, ok, same, swept, fingers,
               skipped: dict) -> tuple[float, bool]:
    """Print one set's figures; returns (median ratio over objects both solve, 100 % success)."""
    n = len(s.objects)
    print(f"\n== {s.name}: {n} objects, start kappa = {np.round(s.start, 2).tolist()} 1/m"
          + (f" ({s.drawn} drawn)" if s.drawn else ""))
    if not s.in_goal:
        print("  INFORMATIONAL, not in the goal line: the paper's single finger (fingers = "
              "\"left\") planning right-side objects as an S-curl (Sec. 5.3 option 3); the "
              "console, with the default robot file's finger pair, plans these with the right "
              "finger (the set above)")
    if fingers:
        print("  this planner's finger: " + ", ".join(
            f"{f} on {fingers.count(f)}" for f in sorted(set(fingers))))
    for why, objs in skipped.items():
        if objs:
            print(f"  skipped, {why}: {len(objs)}: " + ", ".join(
                f"({o[0]:.3f}, {o[1]:.3f}, r={o[2]:.4f}): {r}" for o, r in objs[:3])
                + (" ..." if len(objs) > 3 else ""))
    if n == 0:
        print("  no objects")
        return float("nan"), False
    a0, a1 = np.array(ms[names[0]]), np.array(ms[names[1]])
    ok0, ok1 = np.array(ok[names[0]]), np.array(ok[names[1]])
    lit = np.array(ms[names[3]]) if s.all_methods else None
    print(f"{'method':34s} {'median ms':>10s} {'p90 ms':>8s} {'success':>8s}"
          + (f" {'speed-up vs literal':>20s} {'min per object':>15s}" if lit is not None else ""))
    for k in names:
        if not ms[k]:
            continue
        a = np.array(ms[k])
        line = (f"{k:34s} {np.median(a):10.2f} {np.percentile(a, 90):8.2f} "
                f"{100 * np.mean(ok[k]):7.1f}%")
        if lit is not None:
            line += f" {np.median(lit) / np.median(a):19.1f}x {np.min(lit / a):14.1f}x"
        print(line)
    both = ok0 & ok1
    for label, mask in (("CasADi sqpmethod fails", ok0 & ~ok1),
                        ("this planner fails", ~ok0 & ok1), ("both fail", ~ok0 & ~ok1)):
        if mask.any():
            objs = [s.objects[i] for i in np.flatnonzero(mask)]
            print(f"  {label} on {mask.sum()}: " + ", ".join(
                f"({o[0]:.3f}, {o[1]:.3f}, r={o[2]:.4f})" for o in objs[:6])
                + (" ..." if len(objs) > 6 else ""))
    if swept:
        print(f"  CasADi sqpmethod plans that sweep the arm body into the object: {swept} "
              f"(it checks no clearance)")
    print(f"  all {n} objects, whatever the outcome (a failing method timed until it gives up): "
          f"this planner {np.median(a0):.3f} ms | CasADi sqpmethod {np.median(a1):.3f} ms "
          f"(medians) -> {np.median(a1) / np.median(a0):.2f}x")
    if not both.any():
        print("  no object solved by both: no speed ratio on this set")
        return float("nan"), bool(ok0.all())
    m0, m1 = float(np.median(a0[both])), float(np.median(a1[both]))
    ratio = a1[both] / a0[both]
    print(f"  on the {both.sum()} objects both solve: this planner {m0:.3f} ms | CasADi "
          f"sqpmethod {m1:.3f} ms (medians) -> {m1 / m0:.2f}x faster (per object: median "
          f"{np.median(ratio):.2f}x, worst {ratio.min():.2f}x)")
    worst = np.argsort(ratio)[:3]
    objs = [o for o, b in zip(s.objects, both) if b]
    print("  slowest relative to CasADi sqpmethod: " + "; ".join(
        f"({objs[i][0]:.3f}, {objs[i][1]:.3f}, r={objs[i][2]:.4f}) {a0[both][i]:.2f} vs "
        f"{a1[both][i]:.2f} ms" for i in worst))
    if same:
        differ = [d for d in same if d[1] >= 1e-3]
        print(f"  same final configuration as CasADi sqpmethod (max |dkappa| < 1e-3): "
              f"{100 * (1 - len(differ) / len(same)):.0f}% of {len(same)} plans both solved"
              + ("" if not differ else "; differ (another local minimum; |kappa - start| this "
                 "planner vs CasADi) on " + ", ".join(
                     f"({o[0]:.3f}, {o[1]:.3f}, r={o[2]:.4f}) by {d:.3g} 1/m ({e0:.1f} vs "
                     f"{e1:.1f} 1/m" + (", CasADi's plan sweeps into it)" if sw else ")")
                     for o, d, sw, e0, e1 in differ[:4]) + (" ..." if len(differ) > 4 else "")))
    if lit is not None:
        goal_lit = np.min(lit / a0) >= GOAL_VS_LITERAL
        print(f"  goal: >= {GOAL_VS_LITERAL:g}x the literal port on every object ... "
              f"{'met' if goal_lit else 'NOT met'}")
    return m1 / m0, bool(ok0.all())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=5, help="timed repeats per object and method")
    ap.add_argument("--quick", action="store_true", help="coarser object grid")
    ap.add_argument("--no-ipopt", action="store_true")
    ap.add_argument("--random", type=int, default=30,
                    help="random objects per quadrant (0: fixed grid only)")
    ap.add_argument("--seed", type=int, default=None,
                    help="seed of the random sets (default: drawn from the clock, printed)")
    ap.add_argument("--clock", choices=tuple(CLOCKS), default="cpu",
                    help="cpu: CPU time of the planning thread (default; robust on a shared "
                         "machine, every method runs in this thread), wall: wall-clock time")
    ap.add_argument("--right-start", choices=("straight", "curled"), default="straight",
                    help="start of the informational left-finger-only right-quadrant set: "
                         "straight, or curled to the extreme curvature into the right quadrant "
                         "(paper Sec. 5.3, option 3)")
    ap.add_argument("--no-single-finger", action="store_true",
                    help="skip the informational set (right-quadrant objects planned with the "
                         "left finger only, as an S-curl)")
    args = ap.parse_args()
    seed = args.seed if args.seed is not None else time.time_ns() % 2**32

    robot = robots.load("soft-arm")
    n = robot.n_segments
    straight = np.zeros(n)
    curled = np.full(n, -robot.kappa_max)
    sided = SidedPlanner(robot)          # what the console plans: the finger on the object's side
    left_only = sided.left               # Algorithm 1 for the left finger (the same instance)
    t = time.perf_counter()
    cas_left = CasadiPlanner(robot, "sqpmethod")
    cas = SidedCasadiPlanner(robot, cas_left)
    ipo = None if args.no_ipopt else SidedCasadiPlanner(robot, CasadiPlanner(robot, "ipopt"))
    build_ms = (time.perf_counter() - t) * 1e3
    print(f"robot file: [gripper] fingers = {'both' if 'right' in robot.gripper.sides else 'left'}"
          f" (this planner plans with the finger on the object's side)")

    grid, grid_refused = [], {"refused": []}
    for x, y, r in grid_objects(args.quick):
        try:
            sided.plan(straight, (x, y), r)     # also warms caches (seed table) before timing
            grid.append((x, y, r))
        except GraspRefused as exc:
            grid_refused["refused"].append(((x, y, r), exc.reason))
    sets = [(ObjectSet("fixed grid, left quadrant", straight, grid, sided, cas, all_methods=True),
             grid_refused)]
    if args.random > 0:
        rng = np.random.default_rng(seed)
        sets.append(random_set("random left quadrant", sided, cas, straight, -1.0, args.random,
                               rng))
        sets.append(random_set("random right quadrant (right finger)", sided, cas, straight,
                               1.0, args.random, rng))
        if not args.no_single_finger:
            sets.append(random_set(
                f"random right, left finger only ({args.right_start} start)", left_only,
                cas_left, curled if args.right_start == "curled" else straight, 1.0,
                args.random, rng, in_goal=False))

    from core.planning.grasp_solver import compiled_kernel
    print("this planner's Newton iterations: " + (
        "compiled (numba, core.planning.solver_jit)" if compiled_kernel() is not None else
        "pure Python (numba not installed, or GRASP_SOLVER_JIT=0)"))
    print(f"Grasp planner benchmark (Algorithm 1), one run; delta_d = {robot.delta_d} m; per "
          f"object the best of {args.repeats} runs ({max(1, args.repeats // 2)} for IPOPT, 2 for "
          f"the literal port), {args.clock} time; this planner and CasADi sqpmethod alternate "
          f"run by run, the other methods follow object by object.")
    if args.random > 0:
        print(f"random sets: seed {seed} (repeat with --seed {seed}), {args.random} graspable "
              f"objects per quadrant, |x| in {QUADRANT_X}, y in {QUADRANT_Y} m, radius in {SIZES} m")
    results = []
    for s, refused in sets:
        out = run_set(s, robot, ipo, args.repeats, CLOCKS[args.clock])
        results.append((s, *report_set(s, *out, refused)))
    print(f"\n(CasADi NLP construction, not timed above: {build_ms:.0f} ms)")
    print(f"\n{'set':48s} {'ratio vs CasADi sqpmethod':>26s} {'this planner success':>21s}")
    for s, ratio, all_ok in results:
        shown = f"{ratio:25.2f}x" if np.isfinite(ratio) else f"{'n/a (none solved by both)':>26s}"
        print(f"{s.name:48s} {shown} {'100 %' if all_ok else 'below 100 %':>21s}"
              + ("" if s.in_goal else "  (informational)"))
    goal = [(r, a) for s, r, a in results if s.in_goal]
    judged = [(r, a) for r, a in goal if np.isfinite(r)]
    met = bool(judged) and all(r >= GOAL_VS_CASADI for r, _ in judged) and all(
        a for _, a in goal)
    print(f"\ngoal: >= {GOAL_VS_CASADI:g}x CasADi sqpmethod by median (objects both solve) on "
          f"every goal set with such objects, at 100 % success ... {'met' if met else 'NOT met'}"
          + ("" if all(s.in_goal for s, _, _ in results) else
             " (the informational left-finger-only set is not a goal set: with the default "
             "robot file the console plans right-side objects with the right finger)"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
