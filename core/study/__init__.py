"""Design studies: compute a soft arm's figures of merit for every variant of a robot file.

A variant is the base robot file with some ``section.key`` values changed (issue 30). Each
variant's file is written into the study directory (so ``serve.py --robot`` opens it) and its
metrics become one row of ``results.csv`` / ``results.parquet`` (units in column names). Each
finished variant is also written as ``variants/<name>.json`` the moment it completes (in any
order), so a killed study resumes where it stopped. ``report.html`` plots each metric
(self-contained SVG) and ``plots/<metric>.png`` each metric over the varied keys
(:mod:`core.study.plots`, matplotlib from the ``study`` extra). The variants run through whatever
``map_fn`` the caller passes: the command line's local process pool or Ray (``--ray``); this
library starts no process or thread itself.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import re
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from core.robot_schema import tomllib  # (Python 3.10: tomli)
from core.robot_schema import RobotFileError
from core.robot_text import set_keys
from core.robots import ROBOTS_DIR, ExtensibleArm, SoftArm, load, parse


@dataclasses.dataclass(frozen=True)
class StudySpec:
    """What to compute per variant.

    Attributes:
        objects: Grasp-and-place objects per seed (spots A-E of the paper, cycled).
        seeds: Seeds per object.
        reach_step: Grid step (m) of the reachable-area map.
        capture_spacing: Grid step (m) of the capture region.
        time_limit_s: Simulated time limit per trial (s).
        ik_grid: Extensible arm: tip-IK targets per axis of the target grid (0: no IK metric).
        ik_reach: Extensible arm: half-width (m) of the target box ``[-R, R]^2 x [0, R]``;
            ``None``: :func:`run_study` puts the longest reach ``count * rack_max`` among the
            study's variants here, so every variant is scored on the same targets.
        slip_points: Extensible arm: targets of the repeatability-under-slip study (0: none).
        slip_repeats: Moves from the retracted pose to each of those targets.
    """

    objects: int = 5
    seeds: int = 1
    reach_step: float = 0.02
    capture_spacing: float = 0.01
    time_limit_s: float = 60.0
    ik_grid: int = 4
    ik_reach: float | None = None
    slip_points: int = 3
    slip_repeats: int = 5


def source_path(robot: str) -> Path:
    """The TOML file of a shipped robot name or a path."""
    return Path(robot) if robot.endswith(".toml") else ROBOTS_DIR / f"{robot}.toml"


def parse_vary(items: Sequence[str]) -> dict[str, list[float]]:
    """``["segments.count=4,6"]`` -> ``{"segments.count": [4, 6]}`` (ints stay ints).

    Raises:
        ValueError: an item is not ``KEY=V1,V2,...`` with numbers; the message names it.
    """
    out: dict[str, list[float]] = {}
    for item in items:
        key, sep, values = item.partition("=")
        if not sep or "." not in key or not values:
            raise ValueError(f"--vary {item!r}: expected SECTION.KEY=V1,V2,...")
        vals: list[float] = []
        for v in values.split(","):
            try:
                num: float = int(v) if re.fullmatch(r"[+-]?\d+", v.strip()) else float(v)
            except ValueError:
                raise ValueError(f"--vary {key}: {v!r} is not a number") from None
            if not math.isfinite(num):
                raise ValueError(f"--vary {key}: {v!r} is not a finite number")
            vals.append(num)
        out[key.strip()] = vals
    return out


def variant_text(text: str, changes: Mapping[str, float], name: str, label: str) -> str:
    """The robot file ``text`` with ``changes`` applied in place (comments kept), renamed.

    Raises:
        RobotFileError: a key is not in its section exactly once (the message names it).
    """
    out, found = set_keys(text, changes)
    for key, n in found.items():
        if n != 1:
            raise RobotFileError(f"{label}: unknown key {key!r} (no such field in the file)")
    return re.sub(r'(?m)^name = "[^"]+"', f'name = "{name}"', out, count=1)


def variants(robot: str, vary: Mapping[str, Sequence[float]]) -> list[tuple[str, dict[str, float], str]]:
    """Every combination of the varied values: ``(name, changes, robot file text)``.

    Each text is parsed with the robot schema here, so an unknown key or a value out of
    bounds raises :class:`RobotFileError` naming the key before any work starts.
    """
    path = source_path(robot)
    if not path.exists():
        load(robot)  # raises the schema's own "unknown robot" message
    text = path.read_text()
    base = tomllib.loads(text).get("name", path.stem)
    keys = list(vary)
    out = []
    for combo in itertools.product(*(vary[k] for k in keys)):
        changes = dict(zip(keys, combo))
        name = base + "".join(f"_{k.replace('.', '-')}={v}" for k, v in changes.items())
        vtext = variant_text(text, changes, name, path.name)
        parse(tomllib.loads(vtext), path, label=f"{path.name} with {_fmt(changes)}")
        out.append((name, changes, vtext))
    return out


def _fmt(changes: Mapping[str, float]) -> str:
    return ", ".join(f"{k}={v}" for k, v in changes.items())


def soft_metrics(robot: SoftArm, robot_file: str, spec: StudySpec) -> dict[str, float]:
    """Reachable-grasp area, capture-region area and grasp-and-place success of one soft arm."""
    from core.control.capture import characterise
    from core.control.trials import paper_locations, run_trials, sided_objects
    from core.planning.reachability import PLANNABLE, reachability_map

    r = robot.capture.nominal_object_radius if hasattr(robot, "capture") else 0.0165
    reach_len = float(sum(robot.lengths)) + robot.gripper.length
    reach = reachability_map(robot, r, (-reach_len, reach_len), (0.0, reach_len),
                             spec.reach_step, samples=5000, levels=1)
    area = float((reach.status == PLANNABLE).sum()) * spec.reach_step ** 2
    cmap = characterise(robot, r, spacing=spec.capture_spacing)
    cap = float(cmap.successes) * spec.capture_spacing ** 2
    spots = list(paper_locations().items())
    objs = [(lab, (x, y, r)) for lab, (x, y) in
            (spots[i % len(spots)] for i in range(spec.objects))]
    if "right" in robot.gripper.sides:
        objs = sided_objects(robot, objs, "both")
    results = run_trials(robot_file, objs, spec.seeds, 0, time_limit_s=spec.time_limit_s)
    ok = sum(t.success for t in results)
    return {"reachable_area_m2": area, "capture_area_m2": cap,
            "grasp_place_success": ok / len(results) if results else math.nan,
            "grasp_place_trials": float(len(results))}


def workspace_metrics(robot: ExtensibleArm, samples: int = 20000,
                      voxel: float = 0.02) -> dict[str, float]:
    """Reachable tip-workspace volume: each segment's bend drawn uniformly in the disc
    ``|(dx, dy)| <= d theta_max`` and its extension uniformly in the racks' range (seed 0),
    draws with a rack outside ``[rack_min, rack_max]`` dropped, occupied ``voxel`` cubes counted."""
    from core.kinematics.delta import actuators_from_delta, forward_kinematics

    rng = np.random.default_rng(0)
    shape = (samples, robot.n_segments)
    rad = robot.bend_max * np.sqrt(rng.uniform(0, 1, shape))
    ang = rng.uniform(0, 2 * np.pi, shape)
    dz = rng.uniform(robot.rack_min - robot.L0, robot.rack_max - robot.L0, shape)
    deltas = np.stack([rad * np.cos(ang), rad * np.sin(ang), dz], axis=-1)
    racks = actuators_from_delta(deltas, robot.phi, robot.L0)
    ok = ((racks >= robot.rack_min) & (racks <= robot.rack_max)).all(axis=(-1, -2))
    tips = forward_kinematics(deltas[ok], robot.L0, robot.d)[:, -1, :3, 3]
    cells = {tuple(c) for c in np.floor(tips / voxel).astype(int)}
    return {"workspace_volume_m3": len(cells) * voxel ** 3,
            "configurations_within_rack_limits": float(ok.mean())}


def reach_of(robot: ExtensibleArm) -> float:
    """Upper bound of the tip's distance from the base (m): every segment straight at
    ``rack_max`` (a bent segment's chord is shorter than its arc)."""
    return robot.n_segments * robot.rack_max


def ik_targets(reach: float, per_axis: int) -> np.ndarray:
    """The tip-IK target grid (per_axis**3, 3): cell centres of the box
    ``[-reach, reach]^2 x [0, reach]`` split into ``per_axis`` cells along each axis."""
    c = (np.arange(per_axis) + 0.5) / per_axis
    xs, zs = reach * (2 * c - 1), reach * c
    return np.array([(x, y, z) for x in xs for y in xs for z in zs]).reshape(-1, 3)


def tip_ik_metrics(robot: ExtensibleArm, targets: np.ndarray) -> dict[str, float]:
    """Share of ``targets`` the tip IK (:func:`core.kinematics.delta_ik.solve_tip_ik`, cold
    start, the robot file's ``[ik]`` settings) reaches within its tolerance inside the rack and
    bending limits."""
    from core.kinematics.delta_ik import solve_tip_ik

    ok = [solve_tip_ik(robot, t).reachable for t in targets]
    return {"tip_ik_success": float(np.mean(ok)) if ok else math.nan,
            "tip_ik_targets": float(len(ok))}


def slip_metrics(robot: ExtensibleArm, points: int, repeats: int) -> dict[str, float]:
    """Repeatability under rack slip: Table I's protocol of Hughes 2020
    (:func:`core.control.repeatability.study`, the slip model's defaults, seed 0), open loop
    on the IK's racks and closed loop on the measured tip."""
    from core.control.rack_slip import SlipModel
    from core.control.repeatability import study

    model = SlipModel()
    open_ = study(robot, model, "open", points=points, repeats=repeats, seed=0).summary()
    tip = study(robot, model, "tip", points=points, repeats=repeats, seed=0).summary()
    return {"slip_open_spread_m": open_["mean_spread"], "slip_open_error_m": open_["mean_error"],
            "slip_tip_spread_m": tip["mean_spread"], "slip_tip_error_m": tip["mean_error"]}


def extensible_metrics(robot: ExtensibleArm, spec: StudySpec = StudySpec()) -> dict[str, float]:
    """Workspace volume, tip-IK success over the target grid and repeatability under slip."""
    out = workspace_metrics(robot)
    if spec.ik_grid > 0:
        reach = spec.ik_reach if spec.ik_reach is not None else reach_of(robot)
        out.update(tip_ik_metrics(robot, ik_targets(reach, spec.ik_grid)))
        out["tip_ik_box_m"] = reach
    if spec.slip_points > 0 and spec.slip_repeats > 0:
        out.update(slip_metrics(robot, spec.slip_points, spec.slip_repeats))
    return out


Job = tuple[str, str, dict[str, float], StudySpec, str]
"""``(variant name, its robot file's path, changes, spec, the file's text)``: picklable, and
complete without the study's disk (a Ray worker on another machine writes the text out)."""


def run_variant(job: Job) -> dict[str, Any]:
    """One variant's row (picklable; a failure is a row with its reason)."""
    name, robot_file, changes, spec, text = job
    row: dict[str, Any] = {"variant": name, **changes, "error": ""}
    try:
        path = Path(robot_file)
        if path.is_file() and path.read_text() == text:
            row.update(_metrics(str(path), spec))
        else:  # another machine (a Ray cluster): the text travelled with the job
            import tempfile
            with tempfile.TemporaryDirectory() as tmp:
                local = Path(tmp) / path.name
                local.write_text(text)
                row.update(_metrics(str(local), spec))
    except Exception as exc:  # noqa: BLE001 - a failing variant is a row, the study goes on
        row["error"] = f"{type(exc).__name__}: {exc}"
    return row


def _metrics(robot_file: str, spec: StudySpec) -> dict[str, float]:
    robot = load(robot_file)
    if isinstance(robot, SoftArm):
        return soft_metrics(robot, robot_file, spec)
    return extensible_metrics(robot, spec)


METRICS = ("reachable_area_m2", "capture_area_m2", "grasp_place_success", "workspace_volume_m3",
           "tip_ik_success", "slip_open_spread_m", "slip_tip_error_m")
SMALLER_IS_BETTER = frozenset({"slip_open_spread_m", "slip_tip_error_m"})
"""Metrics whose best variant has the smallest value (the others: the largest)."""


def run_study(robot: str, vary: Mapping[str, Sequence[float]], out: Path, spec: StudySpec,
              *, map_fn: Callable[..., Any] = map,
              progress: Callable[[int, int], None] | None = None,
              plots: bool = True) -> list[dict[str, Any]]:
    """Run (or resume) a study; writes robot files, per-variant JSON, CSV, Parquet and plots.

    ``map_fn(run_variant, jobs)`` runs the pending variants and yields their rows in any order
    (default: the builtin ``map``, in this process; the command line passes a process pool's or
    Ray's ``imap_unordered``: core stays free of processes and threads). Each row is stored as
    ``variants/<name>.json`` as soon as it is yielded, so a study killed mid-way keeps every
    variant finished so far and a rerun computes only the others. ``plots=False`` writes no PNG
    plots (matplotlib missing: :func:`core.study.plots.write_pngs` raises
    :class:`core.study.plots.PlotsUnavailable` once every table is written)."""
    todo = variants(robot, vary)
    spec = with_ik_reach(spec, [text for _, _, text in todo])
    out.mkdir(parents=True, exist_ok=True)
    (out / "variants").mkdir(exist_ok=True)
    rows: dict[str, dict[str, Any]] = {}
    pending = []
    for name, changes, text in todo:
        f = out / f"{name}.toml"
        f.write_text(text)
        stored = _stored_row(out / "variants" / f"{name}.json")
        if stored is not None:
            rows[name] = stored
        else:
            pending.append((name, str(f), changes, spec, text))
    total = len(todo)
    if progress:
        progress(len(rows), total)

    def finish(row: dict[str, Any]) -> None:
        done = out / "variants" / f"{row['variant']}.json"
        part = done.with_suffix(".part")
        part.write_text(json.dumps(row))
        part.replace(done)  # atomic: a kill leaves the old state or the whole row, never half
        rows[row["variant"]] = row
        if progress:
            progress(len(rows), total)

    for row in map_fn(run_variant, pending):
        finish(row)
    ordered = [rows[name] for name, _, _ in todo]
    write_tables(ordered, out)
    from core.study.report import write_html
    write_html(ordered, METRICS, best(ordered), out / "report.html")
    if plots:
        from core.study.plots import write_pngs
        write_pngs(ordered, list(vary), METRICS, best(ordered), out / "plots")
    return ordered


def _stored_row(path: Path) -> dict[str, Any] | None:
    """A finished variant's stored row, or None (not finished, or unreadable: computed again)."""
    try:
        row = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return row if isinstance(row, dict) and "variant" in row else None


def with_ik_reach(spec: StudySpec, texts: Sequence[str]) -> StudySpec:
    """``spec`` with ``ik_reach`` set to the longest reach among the extensible robot files
    ``texts`` (unchanged when it is set, or no file is an extensible arm)."""
    if spec.ik_reach is not None:
        return spec
    reaches = []
    for text in texts:
        robot = parse(tomllib.loads(text), "variant.toml")
        if isinstance(robot, ExtensibleArm):
            reaches.append(reach_of(robot))
    return dataclasses.replace(spec, ik_reach=max(reaches)) if reaches else spec


def write_tables(rows: Sequence[dict[str, Any]], out: Path) -> None:
    """``results.csv`` and ``results.parquet``, one row per variant."""
    import csv

    import pyarrow as pa
    import pyarrow.parquet as pq

    cols: list[str] = []
    for row in rows:
        cols += [c for c in row if c not in cols]
    with open(out / "results.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, cols)
        w.writeheader()
        w.writerows(rows)
    table = pa.table({c: [row.get(c) for row in rows] for c in cols})
    pq.write_table(table, out / "results.parquet")


def best(rows: Sequence[dict[str, Any]]) -> dict[str, str]:
    """The best variant of each metric: the largest value, or the smallest for
    :data:`SMALLER_IS_BETTER` (rows with an error skipped)."""
    out = {}
    for m in METRICS:
        ok = [r for r in rows if not r.get("error") and np.isfinite(r.get(m, math.nan))]
        if ok:
            pick = min if m in SMALLER_IS_BETTER else max
            out[m] = pick(ok, key=lambda r: r[m])["variant"]
    return out
