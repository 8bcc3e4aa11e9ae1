"""Shared rig of the extensible runner tests: the robot, tolerant links, the pty emulator,
started runners, and the independent encoder -> tip computation (imported by
test_extensible_runner.py and test_extensible_bridge.py; not a test module itself).

Links use 1 s timeouts (shipped: 40 / 50 ms; this 2-core box, shared with other jobs and with
the other tests of the parallel part, stalls processes for up to ~0.3 s) so these tests are
about motion, not timing. Every wait has a deadline of many times what it needs.
"""

from __future__ import annotations

import dataclasses
import functools
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Callable, Iterator

import numpy as np
import pytest

from core.kinematics import delta as dk
from core.planning.paths import build_path, plan_path
from core.robots import load
from hw_bridge.config import BridgeConfig
from hw_bridge.extensible_runner import ExtensibleRunner
from hw_bridge.interface import SerialHardware
from hw_bridge.mock import MockHardware
from hw_bridge.transport import SerialTransport

ROOT = Path(__file__).resolve().parents[2]
ROBOT = load("extensible")
N = ROBOT.n_segments
Q0 = np.array([[0.0, 0.0, 0.03], [0.0, 0.0, 0.03]])  # a little extended: short approach
TIP_TOL = 0.003  # m: "within a few mm"


# link timeout and write timeout of the links here: 1 s lost the link of the slipping
# repeatability test on a loaded machine ("no valid STATE for 1008 ms"); the device's watchdog
# stays at its most, 1 s (hw_bridge/device.py refuses a longer one)
SLACK_S = 3.0
WATCHDOG_S = 1.0
HELLO_S = 10.0  # HELLO answer, and the disarmed link's timeout: within the tests' 20 s waits
# CONFIG_ACK patience per try (shipped 50 ms x 4 tries: a loaded run got 'no CONFIG_ACK after 4 tries')
CONFIG_RETRY_S = 1.0


def tolerant() -> BridgeConfig:
    # a just-started emulator on a busy box can take longer than the shipped 500 ms to answer
    # HELLO (a fresh clone's run: "no HELLO answer ... within 500 ms")
    return dataclasses.replace(BridgeConfig.from_robot(ROBOT), link_timeout_s=SLACK_S,
                               watchdog_s=WATCHDOG_S, hello_timeout_s=HELLO_S,
                               config_retry_s=CONFIG_RETRY_S)


def serial_to(port: str) -> SerialHardware:
    """SerialHardware on the emulator's pty, tolerant like :func:`tolerant` (slow writes too)."""
    return SerialHardware(tolerant(), port,
                          transport_factory=lambda url, baud: SerialTransport(
                              url, baud, write_timeout=SLACK_S))


def wait_for(pred: Callable[[], object], timeout: float = 20.0, what: str = "") -> None:
    """Poll ``pred`` every 20 ms until it is true; fail after ``timeout`` s naming ``what``."""
    end = time.monotonic() + timeout
    while not pred():
        assert time.monotonic() < end, f"timed out waiting for {what}"
        time.sleep(0.02)


def tip_from_counts(counts: np.ndarray) -> np.ndarray:
    """Independent: encoders (0 = retracted) -> absolute motor travel -> L = U m -> Delta -> tip."""
    retracted = np.full((N, 3), ROBOT.L0)
    m = np.asarray(counts, float).reshape(N, 3) / ROBOT.counts_per_metre
    m += np.vstack([retracted[:-1] - retracted[1:], retracted[-1:]])  # U^-1 L at retracted
    lengths = np.flip(np.cumsum(np.flip(m, 0), 0), 0)
    return dk.tip_position(ROBOT, dk.delta_from_actuators(lengths, ROBOT.phi, ROBOT.L0))


@functools.lru_cache(maxsize=None)
def short_path(kind: str = "linear", size: float = 0.03, speed: float = 0.1):
    """(MotionPath, waypoints). Plan before starting a runner: planning is seconds of CPU-bound
    Python, which in the loop's process starves it of the GIL (link timeouts, watchdog trips)
    -- the reason the console plans in a worker process."""
    centre = dk.tip_position(ROBOT, Q0)
    return plan_path(ROBOT, build_path(kind, centre, size, "xy"), speed=speed, start_delta=Q0), \
        build_path(kind, centre, size, "xy")


@pytest.fixture
def mock() -> Iterator[MockHardware]:
    hw = MockHardware(ROBOT)
    hw.config = tolerant()
    yield hw
    hw.shutdown()


@pytest.fixture
def runner_on(request: pytest.FixtureRequest) -> Iterator:
    """Factory ``runner_on(hw)``: a started runner, connected (disarmed, as every connect
    leaves it) and then armed by the operator's Arm; closed at teardown."""
    made: list[ExtensibleRunner] = []

    def make(hw, **kw) -> ExtensibleRunner:
        r = ExtensibleRunner(ROBOT, lambda: hw, **kw).start()
        made.append(r)
        assert r.connecting is not None and r.connecting.result(30) is None
        assert r.snapshot.state in ("disarmed", "disconnected")  # connecting never arms
        r.bridge_controls.arm()
        deadline = time.monotonic() + 30.0
        while r.snapshot.state not in ("holding", "fault") and time.monotonic() < deadline:
            time.sleep(0.02)
        assert r.snapshot.state == "holding", r.snapshot
        return r

    yield make
    for r in made:
        r.close()


class Emulator:
    """``python -m hw_bridge.emulator --robot extensible``; its JSON events kept in ``events``."""

    def __init__(self) -> None:
        self.proc = subprocess.Popen([sys.executable, "-m", "hw_bridge.emulator", "--robot",
                                      "extensible"], cwd=ROOT, stdout=subprocess.PIPE, text=True)
        assert self.proc.stdout is not None
        self.port = self.proc.stdout.readline().strip()
        assert self.port.startswith("/dev/"), self.port
        self.events: list[str] = []
        threading.Thread(target=lambda: self.events.extend(self.proc.stdout), daemon=True).start()


@pytest.fixture
def emulator() -> Iterator[Emulator]:
    emu = Emulator()
    yield emu
    if emu.proc.poll() is None:
        emu.proc.terminate()
    emu.proc.wait(timeout=5)
