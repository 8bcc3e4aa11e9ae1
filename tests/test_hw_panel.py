"""Bridge controls (queued operator commands) with MockHardware, and the Hardware panel widgets."""

from __future__ import annotations

import socket
import time

import numpy as np
import viser

from console.panels.hardware import OTHER, HardwarePanel, format_health
from core.robots import load
from hw_bridge.controls import QueuedBridgeControls
from hw_bridge.interface import LifecycleState
from hw_bridge.mock import MockHardware

ROBOT = load("extensible")


def test_queued_commands_drive_the_lifecycle_only_on_the_control_thread() -> None:
    ctl = QueuedBridgeControls()
    mocks: list[MockHardware] = []

    def open_hw(port: str, baud: int) -> MockHardware:
        mocks.append(MockHardware(ROBOT))
        return mocks[-1]

    ctl.connect("mock://", 1_000_000)
    ctl.arm()
    assert not mocks  # enqueueing did nothing by itself
    hw = ctl.apply_pending(None, open_hw)
    try:
        assert hw is mocks[0] and hw.state is LifecycleState.ACTIVE
        for _ in range(5):
            hw.read()
            hw.write(np.full(6, 40))
            time.sleep(0.01)
        ctl.publish(hw.health())
        assert ctl.health().armed
        ctl.disarm()
        hw = ctl.apply_pending(hw, open_hw)
        assert hw.state is LifecycleState.INACTIVE
        ctl.arm()
        ctl.disconnect()
        hw = ctl.apply_pending(hw, open_hw)
        assert hw.state is LifecycleState.UNCONFIGURED
        ctl.arm()  # arming while disconnected is ignored: connect first
        hw = ctl.apply_pending(hw, open_hw)
        assert hw.state is LifecycleState.UNCONFIGURED
    finally:
        for m in mocks:
            m.shutdown()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_panel_builds_and_shows_health() -> None:
    server = viser.ViserServer(host="127.0.0.1", port=_free_port(), verbose=False)
    try:
        ctl = QueuedBridgeControls()
        panel = HardwarePanel(server, ctl, default_port="")
        expected = "" if panel.port_list.value == OTHER else panel.port_list.value
        assert panel.selected_port() == expected
        panel.port_text.value = "/dev/pts/7"
        assert panel.selected_port() == "/dev/pts/7"
        panel.refresh()
        assert "not connected" in panel.readout.content
        hw = MockHardware(ROBOT)
        try:
            hw.configure()
            ctl.publish(hw.health())
            panel.refresh()
            assert "inactive" in panel.readout.content and not panel.arm_btn.disabled
            assert panel.disarm_btn.disabled
            hw.on_error("test fault")
            ctl.publish(hw.health())
            panel.refresh()
            assert "test fault" in panel.readout.content
        finally:
            hw.shutdown()
    finally:
        server.stop()


def test_health_text_marks_watchdog_and_estop() -> None:
    hw = MockHardware(ROBOT)
    try:
        hw.configure()
        h = hw.health()
        assert "watchdog ok" in format_health(h) and "e-stop released" in format_health(h)
    finally:
        hw.shutdown()
