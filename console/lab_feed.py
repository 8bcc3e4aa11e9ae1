"""What the console knows, fed to the recorder (and so to recordings and the live bridge).

The render thread already records the drawn and commanded configuration and the app records
operator actions; these feeds add the rest, called from the threads that already hold it:

* :class:`ControlFeed` -- the soft arm's control pump (20 Hz): control phase, loop timing,
  faults (``core.labdata.telemetry.LoopRecords``) and link health (on change, else once a
  second).
* :func:`feed_grasp` -- the grasp session's worker after it redrew: objects and the newest plan
  (approach circles and waypoints) or the planner's refusal.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np

from core.labdata.telemetry import LoopRecords

LINK_PERIOD_S = 1.0


class ControlFeed:
    """Records from the control process's published views (see the module docstring)."""

    def __init__(self, recorder: Any) -> None:
        self.recorder = recorder
        self._loop = LoopRecords()
        self._link_key: tuple[Any, ...] | None = None
        self._link_at = 0.0

    def on_view(self, view: Any) -> None:
        """Feed the newest view (None while the control process starts)."""
        if view is None:
            return
        for rec in self._loop.records(view.snapshot):
            self.recorder.log(rec["kind"], rec["data"])
        h = view.link
        data: dict[str, Any] = {"device": str(view.device)}
        if h is not None:
            data.update(dataclasses.asdict(h) if dataclasses.is_dataclass(h) else dict(vars(h)))
        key = (data.get("state"), data.get("armed"), data.get("fault"), data.get("lost"))
        now = time.monotonic()
        if key != self._link_key or now - self._link_at >= LINK_PERIOD_S:
            self._link_key, self._link_at = key, now
            self.recorder.log("link", data)


def plan_record(outcome: Any) -> dict[str, Any]:
    """A grasp planner outcome as ``plan`` record data (circles, waypoints; or the refusal)."""
    plan = getattr(outcome, "plan", None)
    if plan is None:
        return {"refusal": getattr(outcome, "refusal", None), "circles": [], "waypoints": []}
    cx, cy = (float(v) for v in np.asarray(plan.center)[:2])
    return {"refusal": None, "center": [cx, cy], "radius": float(plan.radius),
            "circles": [{"x": cx, "y": cy, "r": float(r)} for r in np.asarray(plan.radii)],
            "waypoints": [{"kappa": np.asarray(k, dtype=float).tolist(),
                           "palm": np.asarray(p, dtype=float).tolist()}
                          for k, p in zip(plan.kappas, plan.palm_poses)],
            "total_ms": float(plan.total_ms)}


def feed_grasp(recorder: Any, view: Any, dirty: set[str]) -> None:
    """Record the grasp session's objects and plan when they changed (``dirty``)."""
    if "objects" in dirty:
        recorder.log("objects", {"objects": [dataclasses.asdict(o) for o in view.objects],
                                 "selected": view.selected})
    if "plan" in dirty and view.outcome is not None:
        recorder.log("plan", plan_record(view.outcome))
