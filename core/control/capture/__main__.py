"""``python -m core.control.capture``: the Fig. 6 capture-region characterisation from the command line.

``python -m core.control.capture [--robot NAME|PATH] [--radius R] [--spacing S] [--repeats N] [--seed S]
[--out F.json|F.npz] [--svg F.svg]`` prints the grid (o success, x failure, blank infeasible;
each row's y in mm) and a summary against the disc model, lengths in mm
(:func:`core.control.capture.characterise`). Arguments are SI (m), like the saved map and CSV.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Sequence

from core.control.capture import FAILURE, INFEASIBLE, SUCCESS, CaptureMap, characterise
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
    a = ap.parse_args(argv)
    robot = load(a.robot)
    if not isinstance(robot, SoftArm):
        ap.error(f"{a.robot} is not a soft planar arm")
    from core.labdata.progress import row_progress  # a bar on a terminal, nothing when piped
    try:
        with row_progress("capture grid") as progress:
            cmap = characterise(robot, a.radius, spacing=a.spacing, repeats=a.repeats,
                                seed=a.seed, progress=progress)
    except ValueError as exc:
        ap.error(str(exc))
    if a.csv:
        from core.labdata.results_csv import write_capture_csv
        write_capture_csv(a.csv, cmap)
    if a.out:
        cmap.save(a.out)
    if a.svg:
        a.svg.write_text(cmap.to_svg())
    rows = {SUCCESS: "o", FAILURE: "x", INFEASIBLE: " "}
    print(format_summary(cmap, rows))
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
