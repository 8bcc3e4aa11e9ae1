"""Capture region of the soft gripper: the paper's model and a simulated Fig. 6 characterisation.

**Model** (:class:`CaptureModel`, §5.2 / Fig. 6): "the successful capture region can be
characterised by about half a gripper length in diameter". We take a disc of
``capture.diameter`` (robot file, 0.053 m = half of the 0.106 m gripper) centred where the
planner puts the object centre at the last waypoint: in the gripper-root frame (x along the
heading, y to the closing side) ``(w_off_along, 2 g_off + r)`` - the palm point
``(w_off_along, g_off)`` plus the final approach radius ``r_a = r + g_off`` along the palm normal.

**Characterisation** (:func:`characterise`): like the paper, place the object centre on a 5 mm
grid relative to the gripper (optionally ``repeats`` times with the user's +-1 mm placement
error) and close the gripper with the simulated closing sweep
(:func:`core.control.gripper.close_sweep`). Each cell is a success (dot), a failure (cross) or
infeasible (the disc would overlap the open gripper or the arm, so nobody could place it there).
The result saves to JSON or ``.npz`` and renders to SVG (:meth:`CaptureMap.to_svg`); the
console draws it from the data.

**Sides**: a gripper with two stacked fingers (``[gripper] fingers = "both"``,
:mod:`core.planning.sides`) has a second capture region on its right. ``side="right"``
characterises it on the mirror image of the left grid (y -> -y in the gripper frame), with the
model disc mirrored too; :func:`mirror_agreement` compares the two maps cell by cell.

Command line: ``python -m core.control.capture`` (:mod:`core.control.capture.__main__`).
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Callable

import numpy as np
import numpy.typing as npt

from core.control.gripper import GripperGeometry, capsule_contacts, close_sweep
from core.control.params import SimParams
from core.robots import SoftArm

Array = npt.NDArray[np.float64]
SUCCESS, FAILURE, INFEASIBLE = 1, 0, -1


@dataclasses.dataclass(frozen=True)
class CaptureModel:
    """Disc model of the capture region in the gripper-root frame (m)."""

    center: tuple[float, float]
    diameter: float

    @classmethod
    def from_robot(cls, robot: SoftArm, radius: float | None = None,
                   side: str = "left") -> "CaptureModel":
        """The disc for the finger closing toward ``side`` (right: y mirrored)."""
        r = robot.capture.nominal_object_radius if radius is None else radius
        g = robot.gripper
        normal = 2 * g.g_off + r
        return cls((g.w_off_along, -normal if side == "right" else normal), robot.capture.diameter)

    def contains(self, points: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        """Whether object centres (..., 2) in the gripper frame lie in the disc."""
        p = np.asarray(points, dtype=float)
        return np.hypot(p[..., 0] - self.center[0], p[..., 1] - self.center[1]) <= self.diameter / 2


@dataclasses.dataclass(frozen=True)
class CaptureMap:
    """Grid outcomes in the gripper-root frame; ``rate`` is the success fraction per cell."""

    xs: Array
    ys: Array
    radius: float
    spacing: float
    repeats: int
    outcome: npt.NDArray[np.int8]     # (len(ys), len(xs)): SUCCESS / FAILURE / INFEASIBLE
    rate: Array                       # (len(ys), len(xs)) success fraction over repeats
    model: CaptureModel
    gripper_open: Array               # (M, 2) centreline, for drawing
    gripper_closed: Array
    side: str = "left"                # the finger characterised: left (the paper's) or right

    @property
    def successes(self) -> int:
        return int(np.count_nonzero(self.outcome == SUCCESS))

    def equivalent_diameter(self) -> float:
        """Diameter of the disc with the same area as the success cells."""
        return 2.0 * math.sqrt(self.successes * self.spacing**2 / math.pi)

    def centroid(self) -> tuple[float, float]:
        """Mean position of the success cells (nan if none)."""
        jj, ii = np.nonzero(self.outcome == SUCCESS)
        if ii.size == 0:
            return (math.nan, math.nan)
        return float(self.xs[ii].mean()), float(self.ys[jj].mean())

    def model_agreement(self) -> float:
        """Fraction of feasible cells where the success/failure matches the disc model."""
        X, Y = np.meshgrid(self.xs, self.ys)
        inside = self.model.contains(np.stack([X, Y], -1))
        feas = self.outcome != INFEASIBLE
        return float(np.mean((self.outcome[feas] == SUCCESS) == inside[feas])) if feas.any() else math.nan

    # -- persistence ---------------------------------------------------------------------------
    def to_dict(self) -> dict:
        return {"xs": self.xs.tolist(), "ys": self.ys.tolist(), "radius": self.radius,
                "spacing": self.spacing, "repeats": self.repeats,
                "outcome": self.outcome.tolist(), "rate": self.rate.tolist(),
                "model": {"center": list(self.model.center), "diameter": self.model.diameter},
                "gripper_open": self.gripper_open.tolist(),
                "gripper_closed": self.gripper_closed.tolist(), "side": self.side,
                "summary": {"successes": self.successes,
                            "equivalent_diameter": self.equivalent_diameter(),
                            "centroid": list(self.centroid()),
                            "model_agreement": self.model_agreement()}}

    @classmethod
    def from_dict(cls, d: dict) -> "CaptureMap":
        return cls(np.array(d["xs"], float), np.array(d["ys"], float), float(d["radius"]),
                   float(d["spacing"]), int(d["repeats"]), np.array(d["outcome"], np.int8),
                   np.array(d["rate"], float),
                   CaptureModel(tuple(d["model"]["center"]), float(d["model"]["diameter"])),
                   np.array(d["gripper_open"], float), np.array(d["gripper_closed"], float),
                   str(d.get("side", "left")))

    def save(self, path: str | Path) -> Path:
        """Write ``.json`` or ``.npz`` (by suffix)."""
        path = Path(path)
        d = self.to_dict()
        if path.suffix == ".json":
            path.write_text(json.dumps(d))
        elif path.suffix == ".npz":
            np.savez(path, **{k: np.asarray(v) for k, v in d.items()
                              if k not in ("model", "summary")},
                     model_center=np.array(self.model.center), model_diameter=self.model.diameter)
        else:
            raise ValueError(f"{path}: use a .json or .npz file name")
        return path

    @classmethod
    def load(cls, path: str | Path) -> "CaptureMap":
        path = Path(path)
        if path.suffix == ".json":
            return cls.from_dict(json.loads(path.read_text()))
        with np.load(path) as z:
            d = {k: z[k] for k in z.files}
        d["model"] = {"center": d.pop("model_center"), "diameter": float(d.pop("model_diameter"))}
        if "side" in d:
            d["side"] = str(d["side"])
        return cls.from_dict(d)

    def to_svg(self, scale: float = 4000.0) -> str:
        """Fig. 6 as SVG: blue dots = success, red crosses = failure, grey circle = model."""
        x0, x1 = self.xs[0] - 2 * self.spacing, self.xs[-1] + 2 * self.spacing
        y0, y1 = self.ys[0] - 2 * self.spacing, self.ys[-1] + 2 * self.spacing
        w, h = (x1 - x0) * scale, (y1 - y0) * scale
        px = lambda x: (x - x0) * scale  # noqa: E731
        py = lambda y: (y1 - y) * scale  # noqa: E731
        s = self.spacing * scale * 0.25
        out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w:.0f}" height="{h:.0f}" '
               f'viewBox="0 0 {w:.1f} {h:.1f}"><rect width="100%" height="100%" fill="white"/>']
        for line, colour in ((self.gripper_open, "#333"), (self.gripper_closed, "#999")):
            pts = " ".join(f"{px(x):.1f},{py(y):.1f}" for x, y in line)
            out.append(f'<polyline points="{pts}" fill="none" stroke="{colour}" stroke-width="3"/>')
        cx, cy = self.model.center
        out.append(f'<circle cx="{px(cx):.1f}" cy="{py(cy):.1f}" r="{self.model.diameter / 2 * scale:.1f}" '
                   'fill="none" stroke="grey" stroke-width="2"/>')
        for j, y in enumerate(self.ys):
            for i, x in enumerate(self.xs):
                o = self.outcome[j, i]
                if o == SUCCESS:
                    out.append(f'<circle cx="{px(x):.1f}" cy="{py(y):.1f}" r="{s:.1f}" fill="#1f5fd6"/>')
                elif o == FAILURE:
                    a, b = px(x), py(y)
                    out.append(f'<path d="M{a - s:.1f},{b - s:.1f}L{a + s:.1f},{b + s:.1f}M{a - s:.1f},'
                               f'{b + s:.1f}L{a + s:.1f},{b - s:.1f}" stroke="#d62728" stroke-width="1.5"/>')
        out.append("</svg>")
        return "\n".join(out)


def _initial_overlap(geom: GripperGeometry, p: Array, r: float) -> npt.NDArray[np.bool_]:
    a, b = geom.capsules(0.0)
    dist, _ = capsule_contacts(p, a[0], b[0])
    return np.any(dist < r + geom.half_widths(), axis=1)


def grid_rows(robot: SoftArm, spacing: float, side: str = "left",
              y_range: tuple[float, float] | None = None) -> Array:
    """The grid's y values (gripper frame): around the left finger by default, the exact
    mirror image of those for the right finger."""
    L = robot.gripper.length
    yr = y_range or (-0.2 * L, 0.9 * L)
    ys = np.round(np.arange(yr[0], yr[1] + 1e-9, spacing), 6)
    return -ys[::-1] + 0.0 if side == "right" and y_range is None else ys


def mirror_agreement(left: CaptureMap, right: CaptureMap) -> float:
    """Fraction of the left map's cells whose mirror cell (x, -y) in the right map has the
    same outcome (nan when no cell has a mirror on the right grid)."""
    same = total = 0
    for j, y in enumerate(left.ys):
        jj = np.flatnonzero(np.isclose(right.ys, -y, atol=1e-9))
        if jj.size == 0:
            continue
        for i, x in enumerate(left.xs):
            ii = np.flatnonzero(np.isclose(right.xs, x, atol=1e-9))
            if ii.size:
                total += 1
                same += int(left.outcome[j, i] == right.outcome[jj[0], ii[0]])
    return same / total if total else math.nan


def characterise(robot: SoftArm, radius: float | None = None, *, side: str = "left",
                 spacing: float = 0.005,
                 x_range: tuple[float, float] | None = None,
                 y_range: tuple[float, float] | None = None, repeats: int = 1,
                 placement_noise: float = 0.001, seed: int = 0, params: SimParams | None = None,
                 progress: Callable[[int, int], None] | None = None) -> CaptureMap:
    """Simulate grasps on a grid around the gripper (Fig. 6).

    Args:
        robot: The soft arm (gripper length, offsets, ``[sim.gripper]``).
        radius: Object radius (default the paper's 3.3 cm object).
        side: The finger: ``left`` (the paper's) or ``right`` (a gripper with ``fingers =
            "both"``), whose default grid is the left one mirrored (:func:`grid_rows`).
        spacing: Grid step (the paper: 5 mm).
        x_range, y_range: Grid extent in the gripper frame (default: around the gripper).
        repeats: Placements per cell; repeats > 1 add uniform +-placement_noise (the paper's
            +-1 mm) and a cell succeeds when the majority does.
        seed: Seed of the placement noise.
        params: Simulation parameters (default from the robot file).
        progress: ``(done_rows, rows)`` callback after each grid row.
    """
    if side not in ("left", "right"):
        raise ValueError(f"side must be 'left' or 'right', got {side!r}")
    if side not in robot.gripper.sides:
        raise ValueError("this gripper closes to its left only ([gripper] fingers = \"left\")")
    if spacing <= 0 or repeats < 1:
        raise ValueError(f"need spacing > 0 and repeats >= 1, got {spacing}, {repeats}")
    p = SimParams.from_robot(robot) if params is None else params
    r = robot.capture.nominal_object_radius if radius is None else float(radius)
    if not r > 0:
        raise ValueError(f"object radius must be > 0, got {r}")
    geom = GripperGeometry.from_params(robot.gripper.length, p.gripper, p.arm_half_width,
                                       robot.gripper.fingers)
    L = robot.gripper.length
    xr = x_range or (-0.3 * L, 1.2 * L)
    xs = np.round(np.arange(xr[0], xr[1] + 1e-9, spacing), 6)
    ys = grid_rows(robot, spacing, side, y_range)
    rng = np.random.default_rng(seed)
    outcome = np.empty((len(ys), len(xs)), np.int8)
    rate = np.zeros((len(ys), len(xs)))
    for j, y in enumerate(ys):
        cells = np.stack([xs, np.full_like(xs, y)], -1)
        infeasible = _initial_overlap(geom, cells, r)
        wins = np.zeros(len(xs))
        for k in range(repeats):
            pts = cells + (rng.uniform(-placement_noise, placement_noise, cells.shape) if k else 0.0)
            wins += close_sweep(geom, pts, r).captured
        rate[j] = wins / repeats
        outcome[j] = np.where(infeasible, INFEASIBLE, np.where(rate[j] > 0.5, SUCCESS, FAILURE))
        if progress:
            progress(j + 1, len(ys))
    closed = close_sweep(geom, np.array([[1e3, 1e3]]), r).turn[0]
    return CaptureMap(xs, ys, r, spacing, repeats, outcome, rate,
                      CaptureModel.from_robot(robot, r, side), geom.centreline(0.0)[0, 1:],
                      geom.outline(closed)[0 if geom.both else 1:], side)
