"""What the Paths panel asks its planner worker for, and a plan still being computed there.

A :class:`PathRequest` is the operator's choice plus the posture and box obstacles it starts
from: an unchanged request is not planned again, and Execute runs a preview only while its request
still holds. A :class:`PendingPlan` is one request in the worker process, with when it started
(the panel counts its seconds and gives up after ``PLAN_TIMEOUT_S``, ``console.panels.extensible.paths``).
"""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class PathRequest:
    """What the operator asked for (lengths in m, speed in m/s)."""

    kind: str
    plane: str
    size: float
    speed: float
    start: tuple[float, ...]  # flattened commanded posture the path starts from
    obstacles: int = 0  # version of the box obstacles it was planned around


@dataclasses.dataclass
class PendingPlan:
    """A plan in the worker: what was asked, since when (perf_counter s)."""

    req: PathRequest
    waypoints: Array
    future: cf.Future
    started: float
