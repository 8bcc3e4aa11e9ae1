"""Bridge controls (queued operator commands) with MockHardware; the console's Hardware panel
(operator-only actions, viewers' edits snapped back, faults notified once to every browser, the
mock / no-controls explanation); and hardware_setup.attach building the services (the loop's
``bridge_controls``)."""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np
import pytest
import viser

from console.core.access import AccessControl
from console.core.hardware_attachment import HardwareAttachment
from console.core.hardware_setup import attach
from console.panels.common.hardware import (OTHER, FaultTracker, HardwarePanel, format_health,
                                     no_controls_text)
from core.robots import load
from hw_bridge.controls import QueuedBridgeControls
from hw_bridge.interface import LifecycleState, LinkHealth
from hw_bridge.link_supervisor import LinkRefused, LinkSupervisor
from hw_bridge.mock import MockHardware
from fakes import FakeClient, console_app, user

ROBOT = load("extensible")
SOFT = load("soft-arm")


def test_queued_commands_drive_the_lifecycle_only_on_the_control_thread() -> None:
    ctl = QueuedBridgeControls()
    mocks: list[MockHardware] = []

    def open_hw(port: str, baud: int, old: Any) -> MockHardware:
        # This test is about where the commands run, not link timing: a patient link (5 s
        # for a STATE; 1 s, the most a device takes, for its watchdog), so a test thread
        # descheduled under CPU load is not "link lost: no valid STATE for 92 ms" (19.3).
        hw = MockHardware(ROBOT)
        hw.config = dataclasses.replace(hw.config, link_timeout_s=5.0, watchdog_s=1.0)
        mocks.append(hw)
        return hw

    link = LinkSupervisor(None, open_hw)
    strategy = RecordingStrategy()

    def apply_pending(hw: Any, open_hw: Any) -> Any:  # what a loop thread does once per tick
        while not ctl.commands.empty():
            try:
                link.apply(ctl.commands.get_nowait(), strategy)
            except LinkRefused:
                pass
        return link.hw

    ctl.connect("mock://", 1_000_000)
    ctl.arm()
    assert not mocks  # enqueueing did nothing by itself
    hw = apply_pending(None, open_hw)
    try:
        assert hw is mocks[0] and hw.state is LifecycleState.ACTIVE
        for _ in range(5):
            hw.read()
            hw.write(np.full(6, 40))
            time.sleep(0.01)
        ctl.publish(hw.health())
        assert ctl.health().armed
        ctl.disarm()
        hw = apply_pending(hw, open_hw)
        assert hw.state is LifecycleState.INACTIVE
        ctl.arm()
        ctl.disconnect()
        hw = apply_pending(hw, open_hw)
        assert hw.state is LifecycleState.UNCONFIGURED
        ctl.arm()  # arming while disconnected is ignored: connect first
        hw = apply_pending(hw, open_hw)
        assert hw.state is LifecycleState.UNCONFIGURED
    finally:
        for m in mocks:
            m.shutdown()


class RecordingStrategy:
    """An ArmStrategy that only records what the link supervisor asked of the arm."""

    def __init__(self) -> None:
        self.calls: list[str] = []

    def release(self, message: str) -> None:
        self.calls.append(f"release: {message}")

    def hold(self, hw: Any) -> None:
        self.calls.append("hold")


def test_health_text_marks_watchdog_and_estop() -> None:
    hw = MockHardware(ROBOT)
    try:
        hw.configure()
        h = hw.health()
        assert "watchdog ok" in format_health(h) and "e-stop released" in format_health(h)
        tripped = dataclasses.replace(h, watchdog_tripped=True, estop=True, fault="boom")
        text = format_health(tripped)
        assert "watchdog **TRIPPED**" in text and "e-stop **PRESSED**" in text
        assert "**Fault:** boom" in text and "inactive" in text
    finally:
        hw.shutdown()


# -- the console panel ------------------------------------------------------------------------

HEALTH = LinkHealth(state="inactive", port="/dev/pts/9", fault=None, armed=False,
                    watchdog_tripped=False, estop=False, rtt_ms_p50=1.5, rtt_ms_p99=3.0,
                    rtt_ms_last=1.4, sent=10, received=10, lost=0, crc_errors=0, bad_frames=0,
                    device_rx_errors=0, state_age_ms=4.0)


class FakeControls:
    """A BridgeControls that records what the panel enqueued."""

    def __init__(self, health: LinkHealth | None = None) -> None:
        self.calls: list[tuple[Any, ...]] = []
        self.h = health

    def connect(self, port: str, baud: int) -> None:
        self.calls.append(("connect", port, baud))

    def disconnect(self) -> None:
        self.calls.append(("disconnect",))

    def arm(self) -> None:
        self.calls.append(("arm",))

    def disarm(self) -> None:
        self.calls.append(("disarm",))

    def health(self) -> LinkHealth | None:
        return self.h


def make_panel(server: viser.ViserServer, controls: Any, kind: str | None = "emulator",
               port_path: str | None = "/dev/pts/9", robot: Any = ROBOT) -> HardwarePanel:
    hardware = None if kind is None else HardwareAttachment("test", kind=kind,
                                                            port_path=port_path, baud=1_000_000)
    app = console_app(robot, server, panels=(), access=AccessControl("tok"),
                      bridge_controls=controls, hardware=hardware)
    panel = app.add_panel(HardwarePanel)
    assert panel is not None
    return panel


def test_operator_actions_enqueue_exactly_those_commands_and_viewers_none(server) -> None:
    ctl = FakeControls(HEALTH)
    panel = make_panel(server, ctl)
    app = panel.app
    try:
        viewer, operator = FakeClient(11), FakeClient(12)
        app.access.take(operator.client_id, "tok", name="Alice")
        assert panel.port_text.value == "/dev/pts/9" and panel.baud.value == "1000000"

        for button in (panel.connect_btn, panel.arm_btn, panel.disarm_btn,
                       panel.disconnect_btn):
            user(button, viewer)
        user(panel.port_text, viewer, "/dev/ttyEVIL")
        user(panel.baud, viewer, "115200")
        assert ctl.calls == []
        refusals = [body for title, body in viewer.notes if title == "Not allowed"]
        for action in ("connect the hardware", "arm the device", "disarm the device",
                       "disconnect the hardware", "change the serial port",
                       "change the baud rate"):
            assert any(b.startswith(f"Only the operator can {action} — Alice holds control")
                       for b in refusals), (action, refusals)
        assert panel.port_text.value == "/dev/pts/9"  # snapped back for everyone
        assert panel.baud.value == "1000000"

        user(panel.connect_btn, operator)
        user(panel.arm_btn, operator)
        assert ctl.calls == [("connect", "/dev/pts/9", 1_000_000), ("arm",)]
        user(panel.baud, operator, "115200")
        user(panel.port_text, operator, " /dev/ttyACM0 ")
        user(panel.connect_btn, operator)
        user(panel.disarm_btn, operator)
        user(panel.disconnect_btn, operator)
        assert ctl.calls[2:] == [("connect", "/dev/ttyACM0", 115_200), ("disarm",),
                                 ("disconnect",)]
        user(panel.port_text, operator, "")  # no port: a clear message, nothing enqueued
        user(panel.connect_btn, operator)
        assert len(ctl.calls) == 5
        assert any("Type the controller's port" in body for _, body in operator.notes)
        assert not any(title == "Not allowed" for title, _ in operator.notes)
    finally:
        panel.close()


def test_picking_a_listed_port_fills_the_path_and_typing_leaves_the_list(server) -> None:
    ctl = FakeControls(HEALTH)
    panel = make_panel(server, ctl)
    try:
        operator = FakeClient(3)
        panel.app.access.take(operator.client_id, "tok")
        panel.port_list.options = (OTHER, "/dev/ttyUSB0")  # as if the machine listed one
        user(panel.port_list, operator, "/dev/ttyUSB0")
        assert panel.port_text.value == "/dev/ttyUSB0" and panel.selected_port() == "/dev/ttyUSB0"
        user(panel.port_text, operator, "socket://10.0.0.2:5000")
        assert panel.port_list.value == OTHER
        assert panel.selected_port() == "socket://10.0.0.2:5000"
    finally:
        panel.close()


def test_a_new_fault_is_notified_once_to_every_browser(server, monkeypatch) -> None:
    ctl = FakeControls(dataclasses.replace(HEALTH, state="active", armed=True))
    panel = make_panel(server, ctl)
    try:
        clients = {1: FakeClient(1), 2: FakeClient(2), 3: FakeClient(3)}
        monkeypatch.setattr(server, "get_clients", lambda: dict(clients))

        def faults(c: FakeClient) -> list[str]:
            return [body for title, body in c.notes if title == "Hardware fault"]

        panel.refresh()
        assert all(faults(c) == [] for c in clients.values())
        lost = dataclasses.replace(HEALTH, state="unconfigured", fault="link lost: no valid "
                                   "STATE for 45 ms")
        ctl.h = lost
        # The idle thread notices without any call here (a disarmed arm draws no frames) ...
        deadline = time.monotonic() + 30.0  # (the idle thread's next pass: about 0.2 s)
        while not all(faults(c) for c in clients.values()) and time.monotonic() < deadline:
            time.sleep(0.02)
        assert all(faults(c) for c in clients.values()), "the idle refresh missed the fault"
        for _ in range(3):  # ... and further refreshes do not repeat it
            panel.refresh()
            panel.on_state(panel.app.store.display)
        time.sleep(0.6)
        for c in clients.values():
            assert len(faults(c)) == 1 and "link lost: no valid STATE for 45 ms" in faults(c)[0]
        assert "**Fault:** link lost" in panel.readout.content
        assert not panel.connect_btn.disabled and panel.arm_btn.disabled  # reconnect first

        ctl.h = dataclasses.replace(HEALTH, watchdog_tripped=True)  # the next fault: new
        panel.refresh()
        ctl.h = dataclasses.replace(HEALTH, watchdog_tripped=True, estop=True)
        panel.refresh()
        panel.refresh()
        for c in clients.values():
            assert len(faults(c)) == 3
            assert "device watchdog tripped" in faults(c)[1]
            assert "hardware e-stop pressed" in faults(c)[2]
    finally:
        panel.close()


def test_fault_tracker_reports_edges_once_and_a_recurrence_again() -> None:
    t = FaultTracker()
    assert t.update(None) == [] and t.update(HEALTH) == []
    wd = dataclasses.replace(HEALTH, fault="device watchdog tripped", watchdog_tripped=True)
    assert t.update(wd) == ["device watchdog tripped"]  # one item, not two for one trip
    assert t.update(wd) == [] and t.update(None) == []
    assert t.update(HEALTH) == []  # cleared by the operator's Arm
    assert t.update(wd) == ["device watchdog tripped"]  # it happened again


def test_buttons_follow_the_link_state(server) -> None:
    ctl = FakeControls(None)
    panel = make_panel(server, ctl, port_path=None)  # e.g. the soft arm's emulator pty
    try:
        panel.refresh()
        assert "not connected" in panel.readout.content and panel.readout.visible
        assert not panel.note.visible and not panel.connect_btn.disabled
        assert panel.arm_btn.disabled and panel.disarm_btn.disabled
        assert panel.disconnect_btn.disabled and panel.port_text.value == ""
        ctl.h = HEALTH
        panel.refresh()
        assert panel.port_text.value == "/dev/pts/9"  # the port the loop reports
        assert not panel.arm_btn.disabled and panel.disarm_btn.disabled
        assert not panel.disconnect_btn.disabled
        assert not panel.plot.visible  # one round-trip sample: nothing to plot yet
        ctl.h = dataclasses.replace(HEALTH, state="active", armed=True, port="/dev/pts/4",
                                    received=25, rtt_ms_p50=2.5, rtt_ms_p99=7.0)
        panel.refresh()
        assert panel.arm_btn.disabled and not panel.disarm_btn.disabled
        assert "ARMED" in panel.readout.content
        assert panel.port_text.value == "/dev/pts/9"  # filled once, never overwritten
        panel.refresh()  # no new telemetry: no new sample
        t, p50, p99 = panel.plot.data
        assert panel.plot.visible and len(t) == 2 and t[1] >= t[0]
        np.testing.assert_allclose(p50, [1.5, 2.5])
        np.testing.assert_allclose(p99, [3.0, 7.0])
    finally:
        panel.close()


@pytest.mark.parametrize("kind, words", [
    ("mock", "in-process mock device — no serial link to manage"),
    (None, "none attached"),
    ("emulator", "no link controls here; it connects and arms from the Paths panel")])
def test_without_controls_the_panel_says_why_and_disables_everything(
        server, kind: str | None, words: str) -> None:
    panel = make_panel(server, None, kind=kind, port_path=None)
    try:
        operator = FakeClient(5)
        panel.app.access.take(operator.client_id, "tok")
        assert words in panel.note.content and panel.note.visible
        assert not panel.readout.visible and not panel.plot.visible
        assert all(h.disabled for h in (*panel._buttons, panel.port_text, panel.baud,
                                        panel.port_list))
        assert no_controls_text(kind, "Paths") == panel.note.content
        user(panel.connect_btn, operator)  # a stale page's click: told, nothing breaks
        assert any(words in body for _, body in operator.notes)
    finally:
        panel.close()


# -- hardware_setup.attach --------------------------------------------------------------------

def test_attach_takes_the_loops_bridge_controls(monkeypatch) -> None:
    import hw_bridge.extensible_process as ep
    import hw_bridge.soft_arm_link as sal
    import hw_bridge.soft_arm_process as cp

    made: dict[str, Any] = {}

    class FakeControlProcess:
        def __init__(self, robot: Any, device: str, port_path: str | None,
                     cpus: Any = "auto") -> None:
            made["soft"] = (device, port_path)
            made["cpus"] = cpus
            self.bridge_controls = FakeControls()

        def close(self) -> None:
            made["soft_closed"] = True

    class FakeEmulator:
        path = "/dev/pts/77"

        def __init__(self, args: list[str]) -> None:
            made["emulator_args"] = args

        def stop(self) -> None:
            made["emulator_stopped"] = True

    class FakeRunner:
        def __init__(self, robot: Any, store: Any, kind: str, port_path: str | None = None,
                     **_: Any) -> None:
            made["hardware"] = (kind, port_path)
            self.bridge_controls = FakeControls()

        def start(self) -> None:
            made["started"] = True

        def close(self) -> None:
            made["runner_closed"] = "emulator_stopped" not in made  # loop before emulator

    monkeypatch.setattr(cp, "ControlProcess", FakeControlProcess)
    monkeypatch.setattr(sal, "EmulatorProcess", FakeEmulator)
    monkeypatch.setattr(ep, "ExtensibleProcess", FakeRunner)

    store: Any = object()  # the console's store (the extensible runner's StoreLink reads it)
    soft = attach(SOFT, store, "emulator", None)
    out = soft.hardware
    assert made["soft"] == ("emulator", None) and out.kind == "emulator"
    assert made["cpus"] == "auto"  # no partition chosen by the app: the control process picks
    assert soft.bridge_controls is soft.soft_control.bridge_controls
    assert out.port_path is None and out.baud == 1_000_000  # the child knows the pty
    out = attach(SOFT, store, "mock", "/dev/ttyACM3").hardware
    assert made["soft"] == ("emulator", "/dev/ttyACM3") and out.kind == "port"
    assert out.port_path == "/dev/ttyACM3"

    ext = attach(ROBOT, store, "emulator", None)
    out = ext.hardware
    assert out.kind == "emulator" and out.port_path == "/dev/pts/77" and made["started"]
    # The runner's controls, wrapped so that a Connect brings a dead emulator back.
    assert ext.bridge_controls.controls is ext.extensible_runner.bridge_controls
    assert made["hardware"] == ("port", "/dev/pts/77")
    out.close()
    assert made["runner_closed"] and made["emulator_stopped"]

    made.clear()
    # A runner on MockHardware, started (connected, disarmed) with controls for the Hardware
    # panel: its Arm device is the only way to arm it (connecting never arms, issue #27).
    mock = attach(ROBOT, store, "mock", None)
    assert mock.hardware.kind == "mock" and mock.hardware.port_path == "mock://"
    assert mock.bridge_controls is mock.extensible_runner.bridge_controls
    assert made["hardware"] == ("mock", None) and made["started"]


def test_serve_composes_the_hardware_panel_for_the_mock_disarmed(serve_module, tmp_path) -> None:
    args = serve_module.parse_args(["--robot", "extensible", "--hardware", "mock", "--port", "0",
                                    "--data-dir", str(tmp_path)])
    server, app, _ = serve_module.build(args, load("extensible"), "test")
    try:
        panel = app.panel(HardwarePanel)  # the mock connects at start and waits for Arm
        assert not panel.note.visible and not panel.connect_btn.disabled
        assert panel.port_text.value == "mock://"
        # Wait for the link configured (inactive), not just for a first health: one published
        # while the mock was still connecting would not be "disarmed" with Arm enabled yet.
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline and not (
                (h := app.services.bridge_controls.health()) is not None
                and h.state == "inactive"):
            time.sleep(0.05)
        panel.refresh()
        assert "mock://" in panel.readout.content and "disarmed" in panel.readout.content
        assert not panel.arm_btn.disabled  # configured (inactive): Arm device is the next step
    finally:
        app.services.close()
        app.stop()
        server.stop()
