"""Lab records from the control loop's snapshots, shared by the console and the trials CLI.

:class:`LoopRecords` turns each new ``hw_bridge.loop.LoopSnapshot`` (duck-typed: ``tick``, ``t``,
``control`` (a ``core.control.stack.Telemetry`` or None), ``period_ms``, ``work_ms``, ...,
``overruns``, ``fault``) into console records: ``phase`` when the state machine's phase, reason
or armed flag changes, ``timing`` every snapshot that has timings, ``fault`` when a new fault
appears and, if asked, ``state`` (measured curvature, with the reference as the command).
"""

from __future__ import annotations

from typing import Any

import numpy as np


def plan_data(plan: Any, refusal: str | None = None) -> dict[str, Any]:
    """A grasp plan (``core.planning.plan_types.GraspPlan``, duck-typed) as ``plan`` record data:
    its approach circles and waypoints (curvatures, palm poses), lengths in m; or, for None, the
    planner's ``refusal``. The console (``console.recording.lab_feed.plan_record``) and the
    trials recorder write the same."""
    if plan is None:
        return {"refusal": refusal or "no plan", "circles": [], "waypoints": []}
    cx, cy = (float(v) for v in np.asarray(plan.center)[:2])
    return {"refusal": None, "center": [cx, cy], "radius": float(plan.radius),
            "circles": [{"x": cx, "y": cy, "r": float(r)} for r in np.asarray(plan.radii)],
            "waypoints": [{"kappa": np.asarray(k, dtype=float).tolist(),
                           "palm": np.asarray(p, dtype=float).tolist()}
                          for k, p in zip(plan.kappas, plan.palm_poses)],
            "total_ms": float(plan.total_ms)}


class LoopRecords:
    """Stateful mapping from loop snapshots to records (one instance per loop)."""

    def __init__(self, with_state: bool = False) -> None:
        self.with_state = with_state
        self._tick = -1
        self._phase: tuple[Any, ...] | None = None
        self._fault: str | None = None

    def records(self, snap: Any) -> list[dict[str, Any]]:
        """Records for ``snap`` (empty if this tick was seen already)."""
        if snap is None or snap.tick == self._tick:
            return []
        self._tick = snap.tick
        out: list[dict[str, Any]] = []
        c = snap.control
        if c is not None:
            key = (c.phase, c.reason, c.armed)
            if key != self._phase:
                self._phase = key
                out.append({"kind": "phase", "data": {
                    "phase": c.phase, "reason": c.reason, "armed": bool(c.armed),
                    "tracking_ok": bool(c.tracking_ok), "gripper_closed": bool(c.gripper_closed),
                    "waypoint": int(c.waypoint), "n_waypoints": int(c.n_waypoints),
                    "replans": int(c.replans), "loop_t": float(c.t)}})
            if self.with_state:
                ref = np.asarray(c.kappa_ref, dtype=float)
                meas = ref if c.kappa_meas is None else np.asarray(c.kappa_meas, dtype=float)
                out.append({"kind": "state", "q": meas.tolist(), "command": ref.tolist(),
                            "seq": int(snap.tick), "source": "control"})
        if getattr(snap, "period_ms", None) is not None:
            out.append({"kind": "timing", "data": {
                "tick": int(snap.tick), "loop_t": float(snap.t),
                "period_ms": float(snap.period_ms), "work_ms": float(snap.work_ms),
                "read_ms": float(getattr(snap, "read_ms", 0.0)),
                "update_ms": float(getattr(snap, "update_ms", 0.0)),
                "write_ms": float(getattr(snap, "write_ms", 0.0)),
                "overruns": int(snap.overruns)}})
        fault = getattr(snap, "fault", None)
        if fault != self._fault:
            self._fault = fault
            if fault:
                out.append({"kind": "fault", "data": {"fault": str(fault)}})
        return out
