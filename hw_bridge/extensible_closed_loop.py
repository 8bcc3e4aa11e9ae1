"""Closed-loop tip positioning on the running extensible arm: runner moves corrected by a tip sensor.

:func:`closed_loop_move` runs :func:`core.control.closed_loop.position` on an
:class:`~hw_bridge.extensible_runner.ExtensibleRunner`: every move (the open-loop IK move, then
each correction) is a runner job (``move_to``, streamed at 100 Hz and waited for until the
encoders settle), and after each move the tip is measured by a :class:`TipSensor`: the mean of
the next ``samples`` fresh, valid frames of a :class:`hw_bridge.mocap.MocapSource` whose first
point is the tip (x, y, z) in metres -- the emulator's ``--tip-port`` stream
(:class:`~hw_bridge.mocap.UdpMocapReceiver`), or motion capture on the real arm.

The encoders still drive every move; only the tip sensor sees rack slip, so only it lets the loop
correct slip (see :mod:`core.control.closed_loop`). Without a tip sensor there is nothing to close
the loop on beyond what the runner already does (it holds each motor at its demand).
"""

from __future__ import annotations

import time

import numpy as np
import numpy.typing as npt

from core.control.closed_loop import ClosedLoopResult, ClosedLoopSettings, position
from hw_bridge.extensible_runner import ExtensibleRunner
from hw_bridge.mocap import MocapSource

Array = npt.NDArray[np.float64]


class TipSensor:
    """The tip as the mean of fresh frames of a mocap-like source.

    Args:
        source: A started :class:`~hw_bridge.mocap.MocapSource` (point 0 = tip x, y, z in m).
        samples: Frames averaged per measurement.
        timeout: Longest wait for them (s); :class:`TimeoutError` after it.
    """

    def __init__(self, source: MocapSource, samples: int = 10, timeout: float = 2.0) -> None:
        if samples < 1:
            raise ValueError(f"samples must be >= 1, got {samples}")
        self.source = source
        self.samples = samples
        self.timeout = timeout

    def measure(self, samples: int | None = None) -> Array:
        """Mean tip of the next ``samples`` (default: the sensor's) valid frames received after
        this call."""
        want = self.samples if samples is None else samples
        if want < 1:
            raise ValueError(f"samples must be >= 1, got {want}")
        t0 = time.monotonic()
        seen: set[int] = set()
        tips: list[Array] = []
        while len(tips) < want:
            if time.monotonic() - t0 > self.timeout:
                raise TimeoutError(f"tip sensor: {len(tips)} of {want} frames in "
                                   f"{self.timeout:.1f} s")
            f = self.source.latest()
            if (f is not None and f.valid and f.t_received > t0 and f.seq not in seen
                    and f.points.shape[0] >= 1 and np.all(np.isfinite(f.points[0]))):
                seen.add(f.seq)
                tips.append(np.asarray(f.points[0], dtype=float))
            else:
                time.sleep(0.002)
        return np.mean(tips, axis=0)


def closed_loop_move(runner: ExtensibleRunner, target: npt.ArrayLike, tip: TipSensor, *,
                     settings: ClosedLoopSettings = ClosedLoopSettings(),
                     timeout: float = 60.0, samples: int | None = None) -> ClosedLoopResult:
    """Move the tip to ``target`` (m) and correct on ``tip`` (blocks; not on the loop thread).

    ``settings.iterations = 0`` is the open loop with a measurement of where it ended.
    ``samples``: tip frames averaged per measurement (default: the sensor's); a tolerance
    below the averaged noise makes every move correct up to ``settings.iterations`` times.

    Raises:
        ValueError: the target is out of reach (nothing moves).
        RuntimeError: a move failed or timed out (the runner holds where it is).
        TimeoutError: the tip sensor sent no fresh frames.
    """
    runner.start()

    def move(lengths: Array) -> None:
        result = runner.wait(runner.move_to(lengths, "closed loop"), timeout)
        if result is None or not result.ok:
            raise RuntimeError("move timed out" if result is None else result.message)

    return position(runner.robot, target, move, lambda: tip.measure(samples), settings=settings)
