"""The soft arm's pleated gripper as drawn: ``static/gripper.stl`` fitted to the robot, open or closed.

The asset (built by ``scripts/make_gripper.py``) is the straight, open gripper of Katzschmann
2015 (Fig. 2): a constraint layer on the closing side and a row of pleats on the other, in the
gripper-root frame of ``core.control.gripper`` (x along the gripper, y to the left where it
closes, z up). :func:`gripper_vertices` scales it to the robot file's ``[gripper] length`` and
``half_width`` and, for the closed state, curls everything beyond the palm around the constraint
layer with constant curvature (``[sim.gripper] closed_turn`` over the finger's length, the same
finger model as the simulator's capture sweep), keeping the layer's length: the finger bends,
it does not stretch. The arm view sends both shapes once and then moves them by one pose.
A gripper with two fingers (``[gripper] fingers = "both"``, :mod:`core.planning.sides`) is drawn
as two half-height copies stacked on the same palm (the pair as tall as one), the lower one the
mirror image of the upper, each curling toward its own side.
Pure numpy (plus trimesh to read the file).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import numpy.typing as npt

from core.robots import SoftArm

Array = npt.NDArray[np.float64]

ASSET = Path(__file__).resolve().parents[2] / "static" / "gripper.stl"
NEUTRAL_Y = 0.725  # the constraint layer's middle (in half-widths; scripts/make_gripper.py)


@dataclasses.dataclass(frozen=True)
class GripperShape:
    """What the drawn gripper is fitted to (m, rad), from the robot file."""

    length: float
    half_width: float
    palm_length: float
    closed_turn: float
    fingers: str = "left"     # "left" (the paper's) or "both" (two stacked fingers)

    @classmethod
    def of(cls, robot: SoftArm) -> GripperShape:
        """The soft arm's gripper (``[gripper]`` and ``[sim.gripper]``)."""
        g, sim = robot.gripper, robot.sim.gripper
        return cls(float(g.length), float(g.half_width), float(sim.palm_length),
                   float(sim.closed_turn), str(g.fingers))


def load_asset(path: Path = ASSET) -> tuple[Array, npt.NDArray[np.int64]]:
    """Vertices (V, 3) and faces (F, 3) of the asset, as stored (metres, gripper frame)."""
    import trimesh

    mesh = trimesh.load(path, force="mesh")
    return np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=np.int64)


def fit(vertices: Array, shape: GripperShape) -> Array:
    """The asset scaled so it spans ``[0, length]`` along x and ``±half_width`` across."""
    v = np.asarray(vertices, dtype=float)
    lo, hi = v.min(0), v.max(0)
    out = v.copy()
    out[:, 0] = (v[:, 0] - lo[0]) * (shape.length / (hi[0] - lo[0]))
    across = 2.0 * shape.half_width / (hi[1:] - lo[1:])
    out[:, 1:] = (v[:, 1:] - (lo[1:] + hi[1:]) / 2) * across
    return out


def bend(vertices: Array, shape: GripperShape, turn: float) -> Array:
    """Curl the part beyond the palm by ``turn`` (rad) toward +y, around the constraint layer.

    A point at distance ``s = x - palm_length`` along the finger and ``e = y - y_n`` across it
    (``y_n``: the layer's middle) goes to the circle of radius ``R - e`` about the centre of
    curvature ``(palm_length, y_n + R)``, at angle ``s / R`` (``R = finger length / turn``).
    """
    v = np.asarray(vertices, dtype=float).copy()
    finger = shape.length - shape.palm_length
    if abs(turn) < 1e-9 or finger <= 0:
        return v
    radius = finger / turn
    y_n = NEUTRAL_Y * shape.half_width
    s = v[:, 0] - shape.palm_length
    on = s > 0
    phi = s[on] / radius
    e = v[on, 1] - y_n
    v[on, 0] = shape.palm_length + (radius - e) * np.sin(phi)
    v[on, 1] = y_n + radius - (radius - e) * np.cos(phi)
    return v


def to_tip_frame(vertices: Array) -> Array:
    """Gripper frame (x along, y left, z up) -> the arm view's tip frame, whose columns are
    (left, up, along) (``console.scene.skin.planar_matrices``)."""
    v = np.asarray(vertices, dtype=float)
    return np.ascontiguousarray(v[:, [1, 2, 0]])


def gripper_vertices(shape: GripperShape, closed: bool,
                     asset: tuple[Array, npt.NDArray[np.int64]] | None = None,
                     ) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.int64]]:
    """Vertices in the tip frame and faces of the gripper, open or closed."""
    vertices, faces = asset if asset is not None else load_asset()
    v = fit(vertices, shape)
    if shape.fingers != "both":
        if closed:
            v = bend(v, shape, shape.closed_turn)
        return to_tip_frame(v).astype(np.float32), faces
    # Two fingers: the left one in the upper half (z in [0, half_width]), the right one, its
    # mirror image across the gripper's axis, in the lower half.
    if closed:
        v = bend(v, shape, shape.closed_turn)
    half = shape.half_width / 2
    upper = v * np.array([1.0, 1.0, 0.5]) + [0.0, 0.0, half]
    lower = v * np.array([1.0, -1.0, 0.5]) - [0.0, 0.0, half]
    both = np.concatenate([upper, lower])
    faces2 = np.concatenate([faces, faces[:, ::-1] + len(v)])  # mirrored: winding reversed
    return to_tip_frame(both).astype(np.float32), faces2
