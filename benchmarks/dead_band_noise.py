"""How often the arm view's dead band lets a still, noisy soft arm through: the largest source of
a still console's websocket bytes (issue 29 item 1).

``python benchmarks/dead_band_noise.py [--seconds 60] [--seeds 2 3]``

Feeds the shipped ``SoftArmView`` (a local viser server, no viewer) the simulator's measured
curvature noise of an armed, still soft arm at 20 frames/s on a simulated clock and prints how
many frames it sent per simulated minute, with the shipped averaging and with the averaging's
time constant left at ``settle_s`` for steadiness below ``moving_steadiness`` (noise), then how
many of 20 frames of a clean move after it were drawn. The target is 0 frames per minute still.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

Q = np.array([8.0, -5.0, 3.0, 0.0, 2.0, -1.0])  # 1/m, the still pose of the tests
SIGMA = np.array([0.035, 0.11, 0.19, 0.25, 0.31, 0.35])  # 1/m, measured on the sim, armed


def run(seconds: float, seed: int, noise_keeps_tau: bool) -> tuple[int, int]:
    """(frames sent while still over ``seconds``, frames drawn of a 20-frame move after it)."""
    import viser

    import console.scene.arm_view as arm_view
    import console.scene.dead_band as dead_band
    from console.core.model import model_for
    from console.scene.arm_view_factory import make_arm_view
    from core.robots import load

    clock = [100.0]
    shipped = dead_band.DeadBand.average
    arm_view.time.monotonic = lambda: clock[0]  # type: ignore[attr-defined]
    if noise_keeps_tau:
        def average(self: Any, mean: Any, frames: Any, dt: float, steadiness: float = 0.0) -> Any:
            keep = steadiness if steadiness >= self.moving_steadiness else 0.0
            return shipped(self, mean, frames, dt, keep)
        dead_band.DeadBand.average = average  # type: ignore[method-assign]
    server = viser.ViserServer(port=0, verbose=False)
    try:
        view = make_arm_view(server.scene, model_for(load("soft-arm")))
        clock[0] += 5.0
        view.update(Q)
        start = view.frames_sent
        rng = np.random.default_rng(seed)
        for _ in range(int(seconds * 20)):
            clock[0] += 0.05
            view.update(Q + SIGMA * rng.standard_normal(Q.shape))
        still = view.frames_sent - start
        clock[0] += 5.0
        start = view.frames_sent
        for k in range(1, 21):
            clock[0] += 0.05
            view.update(Q + 0.01 * k)
        return still, view.frames_sent - start
    finally:
        server.stop()
        dead_band.DeadBand.average = shipped  # type: ignore[method-assign]


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=60.0)
    p.add_argument("--seeds", type=int, nargs="+", default=[2, 3])
    a = p.parse_args()
    for keep in (False, True):
        for seed in a.seeds:
            still, moved = run(a.seconds, seed, keep)
            label = "noise keeps tau" if keep else "shipped        "
            print(f"{label} seed {seed}: {still * 60.0 / a.seconds:5.1f} frames/min still "
                  f"(target 0), move drawn {moved}/20")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
