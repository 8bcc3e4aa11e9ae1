"""Tip waypoints of Fig. 9's motion paths (Hughes 2020): linear and diagonal traverse, four corners.

Pure geometry, re-exported by :mod:`core.planning.paths`, which turns a polyline into a timed,
limit-respecting joint path.
"""

from __future__ import annotations

import math
from typing import Literal, Sequence

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]
Plane = Literal["xy", "xz", "yz"]
PathKind = Literal["linear", "diagonal", "corners"]
PATH_KINDS: tuple[PathKind, ...] = ("linear", "diagonal", "corners")
_PLANE_AXES = {"xy": (0, 1), "xz": (0, 2), "yz": (1, 2)}


def _check_point(value: npt.ArrayLike, name: str) -> Array:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be 3 numbers (x, y, z), got {value!r}") from None
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be 3 finite numbers (x, y, z), got {value!r}")
    return arr


def _frame(centre: npt.ArrayLike, size: float, plane: Plane) -> tuple[Array, Array, Array]:
    c = _check_point(centre, "centre")
    if isinstance(size, bool) or not isinstance(size, (int, float)) or not math.isfinite(size) \
            or size <= 0:
        raise ValueError(f"size must be a finite number > 0 (m), got {size!r}")
    if plane not in _PLANE_AXES:
        raise ValueError(f"plane must be one of {sorted(_PLANE_AXES)}, got {plane!r}")
    i, j = _PLANE_AXES[plane]
    u, v = np.zeros(3), np.zeros(3)
    u[i], v[j] = 0.5 * size, 0.5 * size
    return c, u, v


def linear_traverse(centre: npt.ArrayLike, size: float, plane: Plane = "xy",
                    axis: Literal[0, 1] = 0) -> Array:
    """Fig. 9A: a straight traverse of length ``size`` through ``centre``.

    Args:
        centre: (3,) midpoint (m).
        size: Length (m).
        plane: Plane of the path; the traverse runs along its first (``axis=0``) or second axis.

    Returns:
        (2, 3) waypoints.
    """
    c, u, v = _frame(centre, size, plane)
    if axis not in (0, 1):
        raise ValueError(f"axis must be 0 or 1, got {axis!r}")
    w = u if axis == 0 else v
    return np.stack([c - w, c + w])


def diagonal_traverse(centre: npt.ArrayLike, size: float, plane: Plane = "xy") -> Array:
    """Fig. 9B: the diagonal of a ``size`` x ``size`` square centred on ``centre``; (2, 3)."""
    c, u, v = _frame(centre, size, plane)
    return np.stack([c - u - v, c + u + v])


def four_corners(centre: npt.ArrayLike, size: float, plane: Plane = "xy",
                 closed: bool = True) -> Array:
    """Fig. 9C: the four corners of a ``size`` x ``size`` square, in turn.

    Returns:
        (5, 3) waypoints (back to the first corner), or (4, 3) if not ``closed``.
    """
    c, u, v = _frame(centre, size, plane)
    corners = [c - u - v, c + u - v, c + u + v, c - u + v]
    return np.stack(corners + [corners[0]] if closed else corners)


def polyline(points: Sequence[Sequence[float]] | npt.ArrayLike) -> Array:
    """Any polyline: (k, 3) finite waypoints, k >= 1 (m)."""
    try:
        arr = np.asarray(points, dtype=float)
    except (TypeError, ValueError):
        raise ValueError("points must be a list of (x, y, z) points") from None
    if arr.ndim != 2 or arr.shape[1] != 3 or arr.shape[0] < 1:
        raise ValueError(f"points must have shape (k, 3) with k >= 1, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError("points must be finite")
    return arr


def build_path(kind: PathKind, centre: npt.ArrayLike, size: float, plane: Plane = "xy") -> Array:
    """Waypoints of a named path (the console's "path, size" choice)."""
    if kind == "linear":
        return linear_traverse(centre, size, plane)
    if kind == "diagonal":
        return diagonal_traverse(centre, size, plane)
    if kind == "corners":
        return four_corners(centre, size, plane)
    raise ValueError(f"path kind must be one of {PATH_KINDS}, got {kind!r}")
