"""The soft arm's distance to a disk on the table, from the planar kinematics alone: the
independent check the obstacle tests hold the planner's plans to."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from core.kinematics import planar


def dense_gap(robot, kappas: npt.ArrayLike, x: float, y: float, r: float) -> np.ndarray:
    """Gap (m) from the arm (backbone +- half-width, straight gripper +- its half-width) to the
    disk (x, y, r), per configuration of ``kappas`` (..., N): 64 backbone samples a segment, 65
    along the gripper (independent of the planner's own clearance check)."""
    bb = planar.sample_backbone(np.asarray(kappas, float), robot.lengths, 64, robot.base_pose)
    body = np.hypot(bb[..., 0] - x, bb[..., 1] - y).min(axis=-1) - robot.half_width
    tip = bb[..., -1, :]
    s = np.linspace(0.0, robot.gripper.length, 65)
    gx = tip[..., 0:1] + s * np.cos(tip[..., 2:3])
    gy = tip[..., 1:2] + s * np.sin(tip[..., 2:3])
    grip = np.hypot(gx - x, gy - y).min(axis=-1) - robot.gripper.half_width
    return np.minimum(body, grip) - r


def swept(kappa_meas: npt.ArrayLike, kappas: npt.ArrayLike) -> np.ndarray:
    """Every configuration on the straight lines in kappa from ``kappa_meas`` through each
    waypoint: (legs, 201, N)."""
    chain = np.vstack([np.asarray(kappa_meas, float), np.asarray(kappas, float)])
    tau = np.linspace(0.0, 1.0, 201)
    return chain[:-1, None, :] + tau[:, None] * (chain[1:] - chain[:-1])[:, None, :]


def swept_gap(robot, kappa_meas: npt.ArrayLike, kappas: npt.ArrayLike, x: float, y: float,
              r: float) -> float:
    """Smallest :func:`dense_gap` over the lines :func:`swept` from ``kappa_meas`` through
    every waypoint."""
    return float(dense_gap(robot, swept(kappa_meas, kappas), x, y, r).min())
