"""The loop runner keeps every tick for the lab (hw_bridge.loop.LoopRunner.tick_ring): on a
simulated clock, one row per tick with its index, loop time, the commands it wrote, the
control's curvatures and its own timing; a tick that overran says how many deadlines it missed,
and the next row's loop time is that many periods later (nothing lost, nothing invented)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from core.labdata.ticks import COMMON, MISSED, PERIOD, T, TICK, WORK, SoftArmTicks, TickRing
from hw_bridge.loop import LoopRunner, SimClock

MS = 1_000_000


@dataclasses.dataclass
class Tel:  # the fields of core.control.stack.Telemetry the tick row reads
    armed: bool
    phase: str
    kappa_target: np.ndarray
    kappa_ref: np.ndarray
    kappa_meas: np.ndarray | None
    commands: np.ndarray


class CountingStack:
    """Writes command k (five channels: k, k+1, ...) at its k-th update (from 0)."""

    armed = True

    def __init__(self) -> None:
        self.k = 0

    def update(self, reading, t, periods=1):
        cmd = np.arange(5.0) + self.k
        self.k += 1
        tel = Tel(True, "approach" if t < 0.05 else "grasp", np.full(2, t), np.full(2, -t),
                  None if self.k == 3 else np.array([reading, reading]), cmd)
        return cmd, tel

    def stop(self, t, reason):
        pass

    def device_fault(self, t, reason):
        return None


class SlowOnce:
    """A device whose read at tick 6 (from 0) 'takes' 25 ms on the injected clock."""

    def __init__(self, clock, box):
        self.clock, self.box, self.n = clock, box, 0

    def read(self, t):
        if self.n == 6:
            self.clock.now_ns += 25 * MS
        self.n += 1
        if self.n >= 10:
            self.box[0]._stop.set()
        return float(self.n)

    def write(self, commands, t):
        return True

    def cylinders(self):
        return None


def test_every_tick_is_one_row_with_what_it_wrote_and_its_overruns() -> None:
    clock = SimClock(0)
    box: list = []
    runner = LoopRunner(SlowOnce(clock, box), CountingStack(), 0.01, clock_ns=clock,
                        sleep_until=clock.sleep_until, timer_ns=clock)
    box.append(runner)
    ring = runner.tick_ring = TickRing(SoftArmTicks(2, 5))
    runner._run()  # the real-time loop body, on the injected clock, in this thread
    b = ring.drain()
    assert b is not None and b.dropped == 0 and ring.drain() is None
    rows = b.rows
    assert list(rows[:, TICK]) == list(range(1, 11))  # every tick, in order
    # Tick 7 (index 6) overran by 25 ms: deadlines 70 and 80 ms missed and skipped.
    assert list(rows[:, MISSED]) == [0, 0, 0, 0, 0, 0, 2, 0, 0, 0]
    assert rows[:, T] == pytest.approx([0.0, 0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.09, 0.10,
                                        0.11])
    assert rows[7, PERIOD] == pytest.approx(30.0) and rows[6, WORK] == pytest.approx(25.0)
    for k, row in enumerate(rows):
        cmd = row[COMMON + 6:COMMON + 11]
        assert list(cmd) == list(np.arange(5.0) + k)  # what that tick wrote
        assert list(row[COMMON:COMMON + 2]) == [row[T], row[T]]  # its target curvature
        meas = row[COMMON + 4:COMMON + 6]
        assert np.all(np.isnan(meas)) if k == 2 else list(meas) == [k + 1, k + 1]
    assert [b.phases[int(c)] for c in rows[:, 3]] == ["approach"] * 5 + ["grasp"] * 5
