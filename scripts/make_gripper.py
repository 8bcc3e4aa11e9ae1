"""Build ``static/gripper.stl``: the soft arm's pleated gripper (Katzschmann 2015, Fig. 2) as a mesh.

``python scripts/make_gripper.py [--robot soft-arm] [--out static/gripper.stl]``

The paper's gripper is one cast silicone finger: an almost inextensible constraint layer on the
side it closes toward and a row of uniform pleats with even gaps on the other side (each pleat
holds a channel; inflated, the pleats push apart and the finger curls toward the layer). The
mesh is drawn straight (open), in the gripper-root frame of ``core.control.gripper``: x along
the gripper from its root, y to the left (the closing side), z up; metres, sized from the robot
file (``[gripper] length, half_width`` and ``[sim.gripper] palm_length``). The console scales it
to the robot it draws and bends it for the closed state (``console.scene.gripper_mesh``), so one
asset serves every soft-arm robot file.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import trimesh

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

PLEATS = 11  # uniform pleats along the finger (the paper's photo shows about a dozen)
PLEAT_FILL = 0.62  # pleat thickness / pitch: the rest is the even gap between pleats
LAYER_Y = (0.45, 1.0)  # constraint layer across y, in half-widths (the closing side)
HEIGHT = 0.82  # pleat and layer half-height, in half-widths
LAYER_STATIONS = 45  # rings along the constraint layer (~2.4 mm apart: a smooth curl when closed)


def rounded_rect(y0: float, y1: float, z0: float, z1: float, r: float,
                 n: int = 6) -> np.ndarray:
    """(P, 2) counter-clockwise convex outline in (y, z) with corner radius ``r``."""
    r = min(r, (y1 - y0) / 2, (z1 - z0) / 2)
    pts = []
    for cy, cz, a0 in ((y1 - r, z0 + r, -np.pi / 2), (y1 - r, z1 - r, 0.0),
                       (y0 + r, z1 - r, np.pi / 2), (y0 + r, z0 + r, np.pi)):
        a = a0 + np.linspace(0.0, np.pi / 2, n)
        pts.append(np.column_stack([cy + r * np.cos(a), cz + r * np.sin(a)]))
    return np.concatenate(pts)


def prism(outline: np.ndarray, x0: float, x1: float, stations: int = 2) -> trimesh.Trimesh:
    """A closed prism: the convex (y, z) ``outline`` swept along x from ``x0`` to ``x1``, with
    ``stations`` rings (more than 2 where the console bends it: its vertices carry the bend)."""
    p, n = len(outline), stations
    xs = np.linspace(x0, x1, n)
    vertices = np.concatenate([np.column_stack([np.full(p, x), outline]) for x in xs])
    i = np.arange(p)
    j = (i + 1) % p
    sides = np.concatenate([
        np.concatenate([np.column_stack([k * p + i, (k + 1) * p + j, k * p + j]),
                        np.column_stack([k * p + i, (k + 1) * p + i, (k + 1) * p + j])])
        for k in range(n - 1)])
    fan = np.arange(1, p - 1)
    last = (n - 1) * p
    cap0 = np.column_stack([np.zeros(p - 2, int), fan, fan + 1])
    cap1 = np.column_stack([np.full(p - 2, last), last + fan + 1, last + fan])
    mesh = trimesh.Trimesh(vertices, np.concatenate([sides, cap0, cap1]), process=True)
    mesh.fix_normals()
    return mesh


def gripper_mesh(length: float, half_width: float, palm_length: float) -> trimesh.Trimesh:
    """The open pleated gripper (see the module docstring for the frame)."""
    hw = half_width
    h = HEIGHT * hw
    collar = prism(rounded_rect(-hw, hw, -hw, hw, 0.6 * hw, 8), 0.0, palm_length * 0.6)
    layer = prism(rounded_rect(LAYER_Y[0] * hw, LAYER_Y[1] * hw, -h, h, 0.25 * hw),
                  0.0, length, stations=LAYER_STATIONS)
    pitch = (length - palm_length) / PLEATS
    pleat_outline = rounded_rect(-hw, LAYER_Y[0] * hw + 0.05 * hw, -h, h, 0.45 * hw)
    pleats = [prism(pleat_outline, palm_length + k * pitch + (1 - PLEAT_FILL) * pitch,
                    palm_length + (k + 1) * pitch, stations=3) for k in range(PLEATS)]
    return trimesh.util.concatenate([collar, layer, *pleats])


def main() -> int:
    from core.robots import load

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robot", default="soft-arm")
    p.add_argument("--out", type=Path, default=REPO / "static" / "gripper.stl")
    a = p.parse_args()
    robot = load(a.robot)
    mesh = gripper_mesh(robot.gripper.length, robot.gripper.half_width,
                        robot.sim.gripper.palm_length)
    mesh.export(a.out)
    lo, hi = mesh.bounds
    print(f"{a.out}: {len(mesh.vertices)} vertices, {len(mesh.faces)} faces, "
          f"bounds x {lo[0]:.4f}..{hi[0]:.4f} y {lo[1]:.4f}..{hi[1]:.4f} "
          f"z {lo[2]:.4f}..{hi[2]:.4f} m")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
