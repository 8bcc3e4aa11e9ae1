"""``python -m core.control.capture``: the Fig. 6 capture-region characterisation from the command line.

``python -m core.control.capture [--robot NAME|PATH] [--radius R] [--spacing S] [--repeats N] [--seed S]
[--out F.json|F.npz] [--svg F.svg]`` prints the grid (o success, x failure, blank infeasible) and
a summary against the disc model (:func:`core.control.capture.characterise`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Sequence

from core.control.capture import FAILURE, INFEASIBLE, SUCCESS, characterise
from core.robots import SoftArm, load


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m core.control.capture", description=__doc__.split("\n")[0])
    ap.add_argument("--robot", default="soft-arm")
    ap.add_argument("--radius", type=float, default=None, help="object radius, m")
    ap.add_argument("--spacing", type=float, default=0.005)
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
    for j in range(len(cmap.ys) - 1, -1, -1):
        print(f"{cmap.ys[j] * 100:6.1f} cm " + "".join(rows[int(o)] for o in cmap.outcome[j]))
    cx, cy = cmap.centroid()
    print(f"object r = {cmap.radius * 100:.2f} cm, grid {cmap.spacing * 1000:.0f} mm: "
          f"{cmap.successes} successes, equivalent diameter {cmap.equivalent_diameter() * 100:.1f} cm "
          f"(model {cmap.model.diameter * 100:.1f} cm), centroid ({cx * 100:.1f}, {cy * 100:.1f}) cm "
          f"(model ({cmap.model.center[0] * 100:.1f}, {cmap.model.center[1] * 100:.1f}) cm), "
          f"agreement with the model {cmap.model_agreement():.0%}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
