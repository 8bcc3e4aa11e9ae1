"""What the console knows, fed to the recorder (and so to recordings and the live bridge).

The render thread already records the drawn and commanded configuration and the app records
operator actions; these feeds add the rest, called from the threads that already hold it:

* :class:`ControlFeed` -- the soft arm's control pump (20 Hz): control phase, loop timing,
  faults (``core.labdata.telemetry.LoopRecords``) and link health unless the Hardware panel
  records it.
* :class:`LinkFeed` -- link health (on change, else once a second); the Hardware panel's
  refresh (both robots) feeds it.
* :func:`feed_grasp` -- the grasp session's worker after its views redrew: objects (with the
  obstacles and the clearance plans keep from them) and the newest plan
  (approach circles and waypoints) or the planner's refusal; :func:`path_plan_record` -- the
  Paths panel's planned tip path (extensible arm).
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any, Callable, Protocol

import numpy as np

from console.core.table_bin import TableBin
from console.core.table_scene import TableObject
from core.labdata.telemetry import LoopRecords, plan_data
from core.planning.obstacles import Obstacle
from core.planning.plan_types import GraspPlan

LINK_PERIOD_S = 1.0


class LinkFeed:
    """``link`` records from link health snapshots: on a change of state, armed, fault or lost
    demands, else once every :data:`LINK_PERIOD_S`."""

    def __init__(self, recorder: Any) -> None:
        self.recorder = recorder
        self._key: tuple[Any, ...] | None = None
        self._at = 0.0

    def on_health(self, device: str, h: Any) -> None:
        data: dict[str, Any] = {"device": str(device)}
        if h is not None:
            data.update(dataclasses.asdict(h) if dataclasses.is_dataclass(h) else dict(vars(h)))
        key = (data.get("state"), data.get("armed"), data.get("fault"), data.get("lost"))
        now = time.monotonic()
        if key != self._key or now - self._at >= LINK_PERIOD_S:
            self._key, self._at = key, now
            self.recorder.log("link", data)


class ControlFeed:
    """Records from the control process's published views (see the module docstring).

    Args:
        recorder: The console's recorder.
        link_elsewhere: True while another feed (the Hardware panel) records link health.
    """

    def __init__(self, recorder: Any, link_elsewhere: Callable[[], bool] = lambda: False) -> None:
        self.recorder = recorder
        self.link_elsewhere = link_elsewhere
        self._loop = LoopRecords()
        self._link = LinkFeed(recorder)

    def on_view(self, view: Any) -> None:
        """Feed the newest view (None while the control process starts)."""
        if view is None:
            return
        for rec in self._loop.records(view.snapshot):
            self.recorder.log(rec["kind"], rec["data"])
        if not self.link_elsewhere():
            self._link.on_health(view.device, view.link)


class GraspOutcome(Protocol):
    """A grasp planning result as recorded (``console.scene.plan_view.Outcome``)."""

    @property
    def plan(self) -> GraspPlan | None: ...

    @property
    def refusal(self) -> str | None: ...


class GraspView(Protocol):
    """What :func:`feed_grasp` records of the grasp session's view
    (``console.scene.plan_view.SessionView``)."""

    @property
    def objects(self) -> tuple[TableObject, ...]: ...

    @property
    def selected(self) -> str | None: ...

    @property
    def obstacles(self) -> tuple[Obstacle, ...]: ...

    @property
    def clearance(self) -> float: ...

    @property
    def bin(self) -> TableBin | None: ...

    @property
    def outcome(self) -> GraspOutcome | None: ...


def plan_record(outcome: GraspOutcome) -> dict[str, Any]:
    """A grasp planner outcome as ``plan`` record data (circles, waypoints; or the refusal)."""
    if outcome.plan is None:
        return {"refusal": outcome.refusal, "circles": [], "waypoints": []}
    return plan_data(outcome.plan)


def path_plan_record(req: Any, waypoints: Any, path: Any) -> dict[str, Any]:
    """A planned tip path (extensible arm, ``core.planning.paths``) as ``plan`` record data:
    its waypoints (tip points, m), the request and the planned duration and worst tip error."""
    return {"refusal": None, "path": str(req.kind), "plane": str(req.plane),
            "size_m": float(req.size), "speed_mps": float(req.speed), "circles": [],
            "waypoints": [{"point": np.asarray(p, dtype=float).tolist()} for p in waypoints],
            "duration_s": float(path.duration), "max_error_m": float(path.max_error)}


def feed_grasp(recorder: Any, view: GraspView, dirty: set[str]) -> None:
    """Record the grasp session's objects and plan when they changed (``dirty``)."""
    if dirty & {"objects", "obstacles"}:
        table_bin = view.bin
        recorder.log("objects", {"objects": [dataclasses.asdict(o) for o in view.objects],
                                 "selected": view.selected,
                                 "obstacles": [dataclasses.asdict(o) for o in view.obstacles],
                                 "clearance": float(view.clearance),
                                 **({} if table_bin is None else {"bin": table_bin.record()})})
    if "plan" in dirty and view.outcome is not None:
        recorder.log("plan", plan_record(view.outcome))
