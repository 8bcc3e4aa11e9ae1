"""Grasp planning in a worker process, so a plan never holds the 100 Hz loop's GIL.

The state machine asks for a plan with a :class:`core.control.grasp_place.PlanRequest`;
:class:`ProcessPlanner` runs the planning function in a ``spawn``-ed worker and returns a
:class:`concurrent.futures.Future` that the loop polls each tick.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
from pathlib import Path
from typing import Any

from core.control.grasp_place import PlanRequest
from core.control.planner_spec import DEFAULT_PLANNER, plan_request, resolve
from hw_bridge.parent_watch import pool_initializer  # a worker ends with its parent

_WORKER_ROBOT: Any = None  # per worker process: the robot loaded once by the initializer


_WORKER_PLAN: Any = None


def _worker_init(robot_source: str, plan_spec: str, cpus: frozenset[int] | None = None) -> None:
    global _WORKER_ROBOT, _WORKER_PLAN
    from core import robots
    if cpus:  # off the real-time CPU its parent runs on (hw_bridge.cpu_partition)
        from hw_bridge.cpu_partition import pin_process
        pin_process(cpus)
    _WORKER_ROBOT = robots.load(robot_source)
    _WORKER_PLAN = resolve(plan_spec)


def _worker_plan(req: PlanRequest) -> Any:
    return plan_request(_WORKER_PLAN, _WORKER_ROBOT, req)


class ProcessPlanner:
    """Planner for the state machine that runs ``plan_grasp`` in a worker process.

    ``plan_spec`` names the planning function (``module:function`` taking
    ``(robot, kappa, center, radius)``). Calling it returns a :class:`concurrent.futures.Future`; the state machine polls ``done()``
    each tick, so planning never blocks the loop (nor holds its GIL). Uses ``spawn`` so no
    loop thread or GUI state is forked.
    """

    def __init__(self, robot_source: str | Path, workers: int = 1,
                 plan_spec: str = DEFAULT_PLANNER,
                 cpus: frozenset[int] | None = None):
        self._args = (workers, str(robot_source), plan_spec, cpus)
        self.restarts = 0
        self.pool = self._new_pool()

    def _new_pool(self) -> cf.ProcessPoolExecutor:
        workers, robot_source, plan_spec, cpus = self._args
        ctx = multiprocessing.get_context("spawn")
        pool = cf.ProcessPoolExecutor(workers, mp_context=ctx, initializer=pool_initializer,
                                      initargs=(_worker_init, robot_source, plan_spec, cpus))
        self.warm = pool.submit(int)  # start the worker now (without waiting for it)
        return pool

    def __call__(self, req: PlanRequest) -> cf.Future:
        """Submit a plan. If the worker process has died (the pool is broken), a new one is
        started and this request fails with a reason, so the task stops and says why."""
        try:
            return self.pool.submit(_worker_plan, req)
        except cf.process.BrokenProcessPool:
            self.pool.shutdown(wait=False, cancel_futures=True)
            self.pool = self._new_pool()
            self.restarts += 1
            failed: cf.Future = cf.Future()
            failed.set_exception(RuntimeError(
                "the planning process had ended unexpectedly; a new one was started, try again"))
            return failed

    def close(self) -> None:
        """Cancel pending plans and end the worker (waits for a plan in progress, ~ms)."""
        self.pool.shutdown(wait=True, cancel_futures=True)
