"""Arm frames a dead band lets through, on a simulated clock: no server load, no timing noise.

``python benchmarks/arm_frames_replay.py [--spot E] [--hold-s 20]``

Runs one grasp-and-place trial of the simulated soft arm headless (``core.control.trials``: the
controller's measured curvatures, motion-capture noise included), then holds the arm still at a
bent pose; samples the measured curvatures at the console's 30 Hz publish rate and feeds them to
an :class:`console.scene.arm_view.ArmView` whose clock is the simulated one. Prints, for the default
dead band and a few others, the arm frames sent per second while the arm moves (as
``benchmarks/bench_viewers.py`` counts them: intervals between frames of at most 0.25 s) and
while it holds still: what the band costs in update rate, free of what a loaded machine adds.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

PUBLISH_HZ = 30.0


def trial_measurements(robot: Any, spot: str, hold_s: float) -> tuple[np.ndarray, np.ndarray,
                                                                     float]:
    """(times, measured curvatures) of a trial then a still hold; and when the hold starts."""
    from core.control.grasp_place import immediate
    from core.control.planner_spec import DEFAULT_PLANNER, resolve
    from core.control.sim import SoftArmSim
    from core.control.sim_loop import SimLoop
    from core.control.stack import ControlStack
    from core.control.trials import paper_locations, run_trial

    samples: list[tuple[float, np.ndarray]] = []

    def observe(c: Any) -> None:
        if c is not None and c.kappa_meas is not None:
            samples.append((c.t, np.array(c.kappa_meas, dtype=float)))

    x, y = paper_locations()[spot]
    run_trial(robot, (x, y, robot.capture.nominal_object_radius), 0, observe=observe)
    t_end = samples[-1][0] if samples else 0.0
    # The still hold: armed at a bent pose, settled, then measured through the same noise.
    plan = resolve(DEFAULT_PLANNER)
    stack = ControlStack(robot, 0.01, immediate(
        lambda req: plan(robot, req.kappa, req.center, req.radius)))
    loop = SimLoop(SoftArmSim(robot, seed=1), stack, 0.01)
    loop.arm()
    loop.run(0.5)
    loop.goto(0.5 * robot.kappa_max * np.array([1.0, -0.6, 0.8, 0.3, -0.9, 0.5]))
    loop.run(30.0)  # it creeps for ~20 s after the move
    hold_at = t_end + 1.0
    t0 = loop.t
    for _ in range(int(hold_s / 0.01)):
        c = loop.tick()
        if c is not None and c.kappa_meas is not None:
            samples.append((hold_at + c.t - t0, np.array(c.kappa_meas, dtype=float)))
    ts = np.array([s[0] for s in samples])
    return ts, np.array([s[1] for s in samples]), hold_at


def replay(robot: Any, ts: np.ndarray, kappas: np.ndarray, band: Any) -> np.ndarray:
    """The (simulated) times the view sent a frame, fed at PUBLISH_HZ."""
    import viser

    import console.scene.arm_view as av
    from console.scene.arm_view_factory import make_arm_view
    from console.core.model import model_for

    class Clock:
        t = 0.0

        def monotonic(self) -> float:
            return self.t

    clock = Clock()
    real = av.time
    server = viser.ViserServer(port=0, verbose=False)
    try:
        av.time = clock  # type: ignore[assignment]  # the view's clock is the simulated one
        view = make_arm_view(server.scene, model_for(robot), dead_band=band)
        start = len(view.sent_at)
        frames = np.arange(ts[0], ts[-1], 1.0 / PUBLISH_HZ)
        idx = np.minimum(np.searchsorted(ts, frames), len(ts) - 1)
        for t, i in zip(frames, idx):
            clock.t = 1000.0 + t
            view.update(kappas[i])
        return np.array(list(view.sent_at)[start:]) - 1000.0
    finally:
        av.time = real  # type: ignore[assignment]
        server.stop()


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--spot", default="E", help="paper location A-E of the trial's object")
    p.add_argument("--hold-s", type=float, default=20.0, help="still hold after the trial (s)")
    a = p.parse_args()

    import bench_viewers as bv
    from console.scene.dead_band import DeadBand
    from core.robots import load

    robot = load("soft-arm")
    ts, kappas, hold_at = trial_measurements(robot, a.spot, a.hold_s)
    default = DeadBand()
    bands = [("default", default),
             ("no moving band", dataclasses.replace(default, moving_position=default.position,
                                                    moving_angle=default.angle)),
             ("none", None)]
    print(f"trial at {a.spot}: {hold_at - 1.0 - ts[0]:.1f} s simulated, then {a.hold_s:.0f} s "
          f"held still; measured curvatures fed at {PUBLISH_HZ:.0f} Hz")
    print(f"{'dead band':16s} | {'trial f/s':>9s} {'moving f/s':>10s} {'moved':>5s} | "
          f"{'still f/s':>9s}")
    for name, band in bands:
        sent = replay(robot, ts, kappas, band)
        trial = sent[sent < hold_at]
        span = hold_at - 1.0 - ts[0]
        ups, share = bv.moving_rate(trial, span)
        still = sent[sent >= hold_at + 2.0]  # after the first frames of the hold
        print(f"{name:16s} | {len(trial) / span:9.1f} {ups:10.1f} {100 * share:4.0f}% | "
              f"{len(still) / (ts[-1] - hold_at - 2.0):9.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
