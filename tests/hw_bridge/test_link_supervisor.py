"""The one link supervisor both arms use: refusals with their reason (nothing opened or armed),
the mock's port, Disconnect blocking Arm until a Connect, and what the arm's strategy is told."""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest

from core.robots import load
from hw_bridge.commands import Arm, Connect, Disarm, Disconnect
from hw_bridge.interface import LifecycleState
from hw_bridge.link_supervisor import (DISARMED, DISCONNECTED, MOCK_PORT, LinkRefused,
                                       LinkSupervisor, open_serial)
from hw_bridge.mock import MockHardware

ROBOT = load("extensible")


class Strategy:
    def __init__(self) -> None:
        self.calls: list[str] = []

    def release(self, message: str) -> None:
        self.calls.append(f"release: {message}")

    def hold(self, hw: Any) -> None:
        self.calls.append(f"hold at {len(hw.positions())} motors")


@pytest.fixture
def mock() -> Any:
    hw = MockHardware(ROBOT)
    # Nothing streams DEMANDs here: with the shipped 50 ms watchdog the device would trip
    # between an Arm and the next check whenever a busy machine stalls the test that long.
    # 1 s (the longest a CONFIG may set) keeps what is checked independent of the wall clock.
    hw.config = dataclasses.replace(hw.config, watchdog_s=1.0)
    try:
        yield hw
    finally:
        hw.shutdown()


def test_arm_disarm_disconnect_connect_on_the_mock(mock: MockHardware) -> None:
    new_links: list[int] = []
    sup = LinkSupervisor(mock, open_serial(ROBOT), lambda: new_links.append(1))
    arm = Strategy()
    sup.apply(Arm(), arm)  # unconfigured: configure, activate, hold
    assert mock.state is LifecycleState.ACTIVE and arm.calls == ["hold at 6 motors"]
    assert new_links == [1] and sup.health().armed
    sup.apply(Disarm(), arm)
    assert mock.state is LifecycleState.INACTIVE and arm.calls[-1] == f"release: {DISARMED}"
    sup.apply(Disarm(), arm)  # not active: nothing to stop
    assert len(arm.calls) == 2

    sup.apply(Disconnect(), arm)
    assert mock.state is LifecycleState.UNCONFIGURED and arm.calls[-1] == f"release: {DISCONNECTED}"
    with pytest.raises(LinkRefused, match="arm refused: disconnected by the operator") as exc:
        sup.apply(Arm(), arm)
    assert mock.state is LifecycleState.UNCONFIGURED and mock.fault == exc.value.fault
    assert not sup.health().armed

    with pytest.raises(LinkRefused, match=f"the mock device is {MOCK_PORT}"):
        sup.apply(Connect("/dev/ttyUSB9", 115200), arm)  # the mock has no port: nothing opened
    assert mock.state is LifecycleState.UNCONFIGURED and len(arm.calls) == 3
    sup.apply(Connect("", 0), arm)  # empty: the current port (the mock), configured, not armed
    assert sup.hw is mock and mock.state is LifecycleState.INACTIVE and not sup.disconnected
    assert arm.calls[-1] == f"release: connecting to {MOCK_PORT}"
    sup.apply(Arm(), arm)
    assert mock.state is LifecycleState.ACTIVE and arm.calls[-1] == "hold at 6 motors"


def test_connect_without_any_port_and_arm_without_a_link_are_refused() -> None:
    sup = LinkSupervisor(None, open_serial(ROBOT))
    arm = Strategy()
    with pytest.raises(LinkRefused, match="connect refused: no port given"):
        sup.apply(Connect("  ", 0), arm)
    with pytest.raises(LinkRefused, match="arm refused: not connected"):
        sup.apply(Arm(), arm)
    assert arm.calls == [] and sup.hw is None and sup.health() is None


def test_connect_to_a_port_that_does_not_exist_fails_with_the_reason() -> None:
    from hw_bridge.config import BridgeConfig
    sup = LinkSupervisor(None, open_serial(ROBOT))
    with pytest.raises(LinkRefused, match="connect refused: ") as exc:
        sup.apply(Connect("/dev/does-not-exist-42", 0), Strategy())
    hw = sup.hw
    assert hw is not None and hw.port == "/dev/does-not-exist-42"
    assert hw.state is LifecycleState.UNCONFIGURED and exc.value.fault == hw.fault
    assert hw.baud == BridgeConfig.from_robot(ROBOT).baud == 1_000_000  # 0: the robot file's
    with pytest.raises(LinkRefused):
        sup.apply(Connect("/dev/does-not-exist-43", 115_200), Strategy())
    assert sup.hw is not hw and sup.hw.baud == 115_200  # a new link at the asked rate
