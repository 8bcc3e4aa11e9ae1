"""``python -m core.control.capture``: the Fig. 6 capture-region characterisation from the command line.

``python -m core.control.capture [--robot NAME|PATH] [--radius R] [--spacing S] [--repeats N] [--seed S]
[--side left|right|both] [--out F.json|F.npz] [--svg F.svg]`` prints the grid (o success, x
failure, blank infeasible; each row's y in mm) and a summary against the disc model, lengths in
mm (:func:`core.control.capture.characterise`). Arguments are SI (m), like the saved map and CSV.
``--side right`` characterises the right finger of a two-finger gripper on the mirrored grid;
``--side both`` both fingers, then how many cells of the right map mirror the left one's
(``--out`` / ``--svg`` / ``--csv`` then get ``-left`` / ``-right`` before their suffix).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Sequence

from core.control.capture import (FAILURE, INFEASIBLE, SUCCESS, CaptureMap, characterise,
                                  mirror_agreement)
from core.robots import SoftArm, load
from core.units import fmt_mm


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m core.control.capture", description=__doc__.split("\n")[0])
    ap.add_argument("--robot", default="soft-arm")
    ap.add_argument("--radius", type=float, default=None, help="object radius (m)")
    ap.add_argument("--spacing", type=float, default=0.005, help="grid spacing (m)")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=None, help="save .json or .npz")
    ap.add_argument("--svg", type=Path, default=None, help="write the Fig. 6 drawing")
    ap.add_argument("--csv", type=Path, default=None,
                    help="also write one CSV row per grid point (units in the header)")
    ap.add_argument("--side", choices=("left", "right", "both"), default="left",
                    help="which finger: left (the paper's), right, or both (two-finger gripper)")
    a = ap.parse_args(argv)
    robot = load(a.robot)
    if not isinstance(robot, SoftArm):
        ap.error(f"{a.robot} is not a soft planar arm")
    from core.labdata.progress import row_progress  # a bar on a terminal, nothing when piped
    sides = ("left", "right") if a.side == "both" else (a.side,)
    maps: dict[str, CaptureMap] = {}
    try:
        for side in sides:
            with row_progress(f"capture grid ({side})") as progress:
                maps[side] = characterise(robot, a.radius, side=side, spacing=a.spacing,
                                          repeats=a.repeats, seed=a.seed, progress=progress)
    except ValueError as exc:
        ap.error(str(exc))
    rows = {SUCCESS: "o", FAILURE: "x", INFEASIBLE: " "}
    for side, cmap in maps.items():
        def named(path: Path) -> Path:
            return path if len(maps) == 1 else path.with_name(f"{path.stem}-{side}{path.suffix}")
        if a.csv:
            from core.labdata.results_csv import write_capture_csv
            write_capture_csv(named(a.csv), cmap)
        if a.out:
            cmap.save(named(a.out))
        if a.svg:
            named(a.svg).write_text(cmap.to_svg())
        if len(maps) > 1:
            print(f"{side} finger:")
        print(format_summary(cmap, rows))
    if len(maps) > 1:
        print(f"right map = mirror image of the left one in "
              f"{mirror_agreement(maps['left'], maps['right']):.0%} of the cells")
    return 0


def format_summary(cmap: CaptureMap, marks: dict[int, str]) -> str:
    """The grid, top row first, each row headed by its y in mm, then the result in mm."""
    step_mm = cmap.spacing * 1e3
    dec = 0 if abs(step_mm - round(step_mm)) < 1e-6 else 1  # whole mm unless the grid is finer
    lines = [f"y (mm)  x from {fmt_mm(cmap.xs[0], dec)} to {fmt_mm(cmap.xs[-1], dec)} mm ->"]
    for j in range(len(cmap.ys) - 1, -1, -1):
        lines.append(f"{fmt_mm(cmap.ys[j], dec):>6}  " + "".join(marks[int(o)]
                                                            for o in cmap.outcome[j]))
    cx, cy = cmap.centroid()
    mx, my = cmap.model.center
    lines.append(
        f"object r = {fmt_mm(cmap.radius)} mm, grid {fmt_mm(cmap.spacing, 0)} mm: "
        f"{cmap.successes} successes, equivalent diameter {fmt_mm(cmap.equivalent_diameter(), 0)} "
        f"mm (model {fmt_mm(cmap.model.diameter, 0)} mm), centroid ({fmt_mm(cx, 0)}, "
        f"{fmt_mm(cy, 0)}) mm (model ({fmt_mm(mx, 0)}, {fmt_mm(my, 0)}) mm), "
        f"agreement with the model {cmap.model_agreement():.0%}")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
