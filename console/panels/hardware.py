"""Hardware panel: pick a port, connect, arm/disarm, and watch link health and faults.

Built directly on a ``viser.ViserServer`` and a :class:`hw_bridge.controls.BridgeControls`, so
the console can wire it to its control thread (or wrap it in a ``console.panels.base.Panel``).
Callbacks only enqueue commands; :meth:`HardwarePanel.refresh` (call it from the render thread,
a few Hz) shows the newest :class:`~hw_bridge.interface.LinkHealth` and notifies new faults.
"""

from __future__ import annotations

import collections
import time

import numpy as np
import viser
import viser.uplot as uplot

from hw_bridge.controls import BridgeControls
from hw_bridge.interface import LinkHealth
from hw_bridge.transport import list_ports

OTHER = "(type a path or URL below)"
BAUDS = ("1000000", "115200", "230400", "460800", "921600", "2000000")
_HISTORY = 200


def format_health(h: LinkHealth | None) -> str:
    """Markdown readout of the link health."""
    if h is None:
        return "**Link:** not connected"

    def ms(v: float | None) -> str:
        return "–" if v is None else f"{v:.2f} ms"

    lines = [
        f"**Link:** {h.state} · {h.port} · {'ARMED' if h.armed else 'disarmed'}",
        f"round trip p50 {ms(h.rtt_ms_p50)} · p99 {ms(h.rtt_ms_p99)}",
        f"sent {h.sent} · received {h.received} · lost {h.lost} · CRC errors {h.crc_errors} "
        f"· bad frames {h.bad_frames} · device rx errors {h.device_rx_errors}",
        f"watchdog {'**TRIPPED**' if h.watchdog_tripped else 'ok'} · "
        f"e-stop {'**PRESSED**' if h.estop else 'released'}",
    ]
    if h.fault:
        lines.append(f"**Fault:** {h.fault}")
    return "  \n".join(lines)


class HardwarePanel:
    """Port picker, baud, Connect/Disconnect, Arm/Disarm, link readout and round-trip plot."""

    def __init__(self, server: viser.ViserServer, controls: BridgeControls,
                 default_port: str = "", default_baud: int = 1_000_000, order: float = 90.0):
        self.server = server
        self.controls = controls
        gui = server.gui
        self.folder = gui.add_folder("Hardware", order=order)
        ports = [p.device for p in list_ports()]
        with self.folder:
            self.port_list = gui.add_dropdown("Port", tuple(ports + [OTHER]),
                                              initial_value=OTHER if not ports else ports[0])
            self.port_text = gui.add_text("Path / URL", default_port,
                                          hint="/dev/ttyACM0, /dev/pts/N, socket://host:port, loop://")
            self.baud = gui.add_dropdown("Baud", BAUDS, initial_value=str(default_baud)
                                         if str(default_baud) in BAUDS else BAUDS[0])
            self.connect_btn = gui.add_button("Connect", icon=viser.Icon.PLUG_CONNECTED)
            self.disconnect_btn = gui.add_button("Disconnect", icon=viser.Icon.PLUG_CONNECTED_X)
            self.arm_btn = gui.add_button("Arm", color="red", icon=viser.Icon.POWER)
            self.disarm_btn = gui.add_button("Disarm", icon=viser.Icon.HAND_STOP)
            self.readout = gui.add_markdown(format_health(None))
            self._t = collections.deque(maxlen=_HISTORY)
            self._rtt = collections.deque(maxlen=_HISTORY)
            self.plot = gui.add_uplot(
                data=(np.zeros(1), np.zeros(1)),
                series=(uplot.Series(label="t (s)"),
                        uplot.Series(label="rtt p50 (ms)", stroke="#1c7ed6", width=2)),
                title="Round trip", aspect=2.0)
        self.connect_btn.on_click(lambda _: self.controls.connect(self.selected_port(),
                                                                  int(self.baud.value)))
        self.disconnect_btn.on_click(lambda _: self.controls.disconnect())
        self.arm_btn.on_click(lambda _: self.controls.arm())
        self.disarm_btn.on_click(lambda _: self.controls.disarm())
        self._last_fault: str | None = None
        self._t0 = time.monotonic()

    def selected_port(self) -> str:
        """Free text wins over the dropdown when filled in."""
        text = self.port_text.value.strip()
        return text if text or self.port_list.value == OTHER else self.port_list.value

    def refresh(self) -> None:
        """Show the latest health; notify each new fault once to every client."""
        h = self.controls.health()
        self.readout.content = format_health(h)
        if h is None:
            return
        self.arm_btn.disabled = h.state != "inactive"
        self.disarm_btn.disabled = h.state != "active"
        if h.rtt_ms_p50 is not None:
            self._t.append(time.monotonic() - self._t0)
            self._rtt.append(h.rtt_ms_p50)
            self.plot.data = (np.asarray(self._t), np.asarray(self._rtt))
        if h.fault and h.fault != self._last_fault:
            for client in self.server.get_clients().values():
                client.add_notification(title="Hardware fault", body=h.fault, color="red",
                                        auto_close_seconds=10.0)
        self._last_fault = h.fault

    def remove(self) -> None:
        """Remove the panel's widgets."""
        self.folder.remove()
