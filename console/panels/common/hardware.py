"""Hardware panel (both robots): pick the serial port, connect, arm/disarm the device, link health.

The panel drives the control loop's :class:`hw_bridge.controls.BridgeControls`, which
``console.core.hardware_setup.attach`` puts into ``app.services.bridge_controls`` (the soft arm's
control process or the extensible arm's runner). Its methods only enqueue; the loop thread
applies them. Without controls (the extensible arm's in-process mock, or a loop that offers
none) the panel says why and disables its inputs.

Restart control loop (shown while the arm's loop process is dead or silent, i.e. while the
header says so, :mod:`console.panels.common.loop_header`): ends the old loop process and starts a new one,
disarmed (:meth:`hw_bridge.loop_process.LoopProcess.restart`), without restarting serve.py.

Sharing: Connect, Disconnect, Arm device, Disarm device, Restart control loop and every change
of port or baud are :func:`~console.panels.common.base.operator_only`; a viewer's edit of the shared port / baud fields snaps
back. A new link fault (a new non-empty ``health().fault``, the device watchdog tripping, the
e-stop being pressed) is shown once to every connected browser and logged to the recording.

Refresh: :meth:`HardwarePanel.on_state` (render thread) at most ``REFRESH_HZ``. The render thread
only runs when the displayed arm state changes (``ConsoleApp._render_loop`` waits for a new
display state), which a disarmed arm never produces, so an idle thread refreshes as well when
``on_state`` has been silent: a fault on an idle link still shows.

What viewers are sent (a still console costs them nothing): the readout only when its text
changes: news (state, arming, fault, watchdog, e-stop, losses and errors) at once, message rates
instead of ever-growing counters, round trips once they moved past ``RTT_BAND``
(:mod:`console.panels.common.steady_figures`); the round-trip plot (0..``axis_top`` ms) only when
p50 or p99 moved a visible amount (``PlotPacer``: ``PLOT_VISIBLE`` of the axis), at most
``PLOT_HZ``; it pauses while nothing visibly changes.
"""

from __future__ import annotations

import collections
import dataclasses
import logging
import threading
import time
from typing import Any, Callable

import numpy as np
import viser
from viser import uplot

from console.panels.common.header import Tone
from console.recording.lab_feed import LinkFeed
from console.panels.common.base import Panel, operator_only
from console.panels.common.plot_data import PlotPacer, axis_top, thin
from console.panels.common.steady_figures import RTT_BAND, CountRate, SteadyFigure
from console.core.state import ArmState
from console.panels.common.events import client_of, target_of
from hw_bridge.controls import BridgeControls
from hw_bridge.interface import LinkHealth
from hw_bridge.transport import list_ports

log = logging.getLogger(__name__)

OTHER = "(type a path or URL below)"
BAUDS = ("1000000", "115200", "230400", "460800", "921600", "2000000")
REFRESH_HZ = 4.0
HISTORY = 240  # round-trip samples in the plot (a minute at REFRESH_HZ)
PLOT_POINTS = 60  # of them drawn (x 3 float64 columns: ~1.4 KB a redraw, to every viewer)
PLOT_HZ = 0.5  # largest redraw rate of the round-trip plot while it visibly changes
PLOT_VISIBLE = 0.1  # of the y axis: smaller moves of p50 / p99 are a steady link's jitter
PLOT_MIN_TOP = 1.0  # ms: the plot's y axis spans at least 0..1 ms
RATE_WINDOW_S = 5.0  # s: message rates are counted over this long
RATE_BAND = (0.1, 2.0)  # a shown rate follows the counted one past 10 % and 2/s
LATE_STATE_MS = 100.0  # the readout tells the last STATE's age once it is this old


def format_health(h: LinkHealth | None, sent_hz: float | None = None,
                  received_hz: float | None = None) -> str:
    """Markdown readout of the link health, with the message rates (None: not known yet)."""
    if h is None:
        return "**Link:** not connected"

    def ms(v: float | None) -> str:
        return "–" if v is None else f"{v:.2f} ms"

    def hz(v: float | None) -> str:
        return "–/s" if v is None else f"{v:.0f}/s"

    late = h.state_age_ms is not None and h.state_age_ms >= LATE_STATE_MS
    age = f" · last STATE {h.state_age_ms:.0f} ms ago" if late else ""
    lines = [
        f"**Link:** {h.state} · `{h.port}` · {'ARMED' if h.armed else 'disarmed'}",
        f"round trip p50 {ms(h.rtt_ms_p50)} · p99 {ms(h.rtt_ms_p99)}{age}",
        (f"sent {hz(sent_hz)} · received {hz(received_hz)} · lost {h.lost} · CRC errors "
         f"{h.crc_errors} · bad frames {h.bad_frames} · device rx errors {h.device_rx_errors}"),
        (f"watchdog {'**TRIPPED**' if h.watchdog_tripped else 'ok'} · "
         f"e-stop {'**PRESSED**' if h.estop else 'released'}"),
    ]
    if h.fault:
        lines.append(f"**Fault:** {h.fault}")
    return "  \n".join(lines)


class HealthReadout:
    """The readout's text for successive health snapshots, steady while the link is (pure, no
    viser): round trips as :class:`SteadyFigure` (``RTT_BAND``), the sent and received counters
    as rates over ``RATE_WINDOW_S`` (:class:`CountRate`; the counters arrive in batches: a 100 Hz
    link read over 2 s measured 94-105/s), shown once they move past ``RATE_BAND``; the rest as
    read.
    """

    def __init__(self) -> None:
        self._p50, self._p99 = SteadyFigure(*RTT_BAND), SteadyFigure(*RTT_BAND)
        self._sent, self._received = CountRate(RATE_WINDOW_S), CountRate(RATE_WINDOW_S)
        self._sent_hz, self._received_hz = SteadyFigure(*RATE_BAND), SteadyFigure(*RATE_BAND)

    def text(self, now: float, h: LinkHealth | None) -> str:
        """The readout at ``now`` (the caller's clock) for ``h``."""
        if h is None:
            return format_health(None)
        shown = dataclasses.replace(h, rtt_ms_p50=self._p50.shown(h.rtt_ms_p50),
                                    rtt_ms_p99=self._p99.shown(h.rtt_ms_p99))
        return format_health(shown, self._sent_hz.shown(self._sent.rate(now, h.sent)),
                             self._received_hz.shown(self._received.rate(now, h.received)))


def header_link(kind: str | None, h: LinkHealth | None) -> tuple[str, Tone | None]:
    """The header's link field for the extensible arm: device, state, arming, or the fault."""
    name = kind or "no hardware"
    if h is None:
        return f"{name} · not connected", None
    if h.fault:
        return f"{name} · {h.fault}", "fault"
    armed = "ARMED" if h.armed else "disarmed"
    ready = h.state in ("active", "inactive")  # inactive: configured, waiting for Arm
    return f"{name} · {h.state} · {armed}", "ok" if ready else "warn"


def extensible_link_health(app: Any) -> LinkHealth | None:
    """The extensible arm's link health: the Hardware panel's controls, or (in-process mock,
    which has none) the runner's own link once it runs; None before either exists."""
    controls = app.services.bridge_controls
    runner = app.services.extensible_runner
    if controls is None and runner is not None and runner.started:
        controls = runner.bridge_controls
    return None if controls is None else controls.health()


def no_controls_text(kind: str | None, owner: str = "Control") -> str:
    """Why the panel has nothing to manage, for the attachment ``kind`` (None: no hardware);
    ``owner`` is the panel whose loop then connects and arms the link itself."""
    if kind == "mock":
        return "**Hardware:** in-process mock device — no serial link to manage."
    if kind is None:
        return "**Hardware:** none attached (kinematic simulation) — no serial link to manage."
    what = "device emulator on a pseudo-terminal" if kind == "emulator" else "serial controller"
    return (f"**Hardware:** {what}. Its control loop offers no link controls here; it connects "
            f"and arms from the {owner} panel.")


class FaultTracker:
    """New faults in a stream of health snapshots, each reported once (pure, no viser)."""

    def __init__(self) -> None:
        self.fault: str | None = None
        self.watchdog = False
        self.estop = False

    def update(self, h: LinkHealth | None) -> list[str]:
        """The faults that are new in ``h`` (None, i.e. no snapshot, changes nothing)."""
        if h is None:
            return []
        new: list[str] = []
        if h.fault and h.fault != self.fault:
            new.append(h.fault)
        text = " ".join(new).lower()
        if h.watchdog_tripped and not self.watchdog and "watchdog" not in text:
            new.append("device watchdog tripped")
        if h.estop and not self.estop and "e-stop" not in text:
            new.append("hardware e-stop pressed")
        self.fault, self.watchdog, self.estop = h.fault, h.watchdog_tripped, h.estop
        return new


class HardwarePanel(Panel):
    """Port picker, baud, Connect/Disconnect, Arm/Disarm device, link readout, round-trip plot."""

    title = "Hardware"
    tab = "Hardware"
    order = 50.0

    def build(self) -> None:
        gui = self.gui
        attachment = self.app.services.hardware
        self.kind: str | None = None if attachment is None else attachment.kind
        self.owner = "Control" if self.app.robot.kind == "planar" else "Paths"
        default_port = (attachment and attachment.port_path) or ""
        default_baud = str((attachment and attachment.baud) or BAUDS[0])
        try:
            ports = [p.device for p in list_ports()]
        except Exception:  # no port listing: free text still works
            log.exception("listing serial ports failed")
            ports = []
        self.note = gui.add_markdown("")
        self.port_list = gui.add_dropdown(
            "Port", (OTHER, *ports), initial_value=default_port if default_port in ports else OTHER,
            hint="Serial ports found on this machine; pick one or type below.")
        self.port_text = gui.add_text("Path / URL", default_port,
                                      hint="/dev/ttyACM0, /dev/pts/N, socket://host:port, loop://")
        bauds = BAUDS if default_baud in BAUDS else (default_baud, *BAUDS)
        self.baud = gui.add_dropdown("Baud", bauds, initial_value=default_baud,
                                     hint="Ignored by the Due's native USB port and by a pty.")
        self.connect_btn = gui.add_button("Connect", icon=viser.Icon.PLUG_CONNECTED)
        self.disconnect_btn = gui.add_button("Disconnect", icon=viser.Icon.PLUG_CONNECTED_X)
        self.arm_btn = gui.add_button("Arm device", color="red", icon=viser.Icon.POWER,
                                      hint="ARM: the device accepts demands (clears a tripped "
                                           "watchdog).")
        self.disarm_btn = gui.add_button("Disarm device", icon=viser.Icon.HAND_STOP)
        self.restart_btn = gui.add_button(
            "Restart control loop", color="orange", icon=viser.Icon.REFRESH, visible=False,
            hint="The arm's control loop process died or went silent: start a new one "
                 "(disarmed; Arm again to move).")
        self._restarting = threading.Lock()
        self.readout = gui.add_markdown(format_health(None))
        self.plot = gui.add_uplot(
            data=(np.zeros(1), np.zeros(1), np.zeros(1)),
            series=(uplot.Series(label="t (s)"),
                    uplot.Series(label="p50 (ms)", stroke="#1c7ed6", width=2),
                    uplot.Series(label="p99 (ms)", stroke="#e8590c", width=1)),
            scales=self._scales(PLOT_MIN_TOP),
            axes=(uplot.Axis(label="t (s)"), uplot.Axis(label="ms", scale="ms")),
            title="Round trip", aspect=2.0, visible=False)
        self._inputs = (self.port_list, self.port_text, self.baud)
        self._buttons = (self.connect_btn, self.disconnect_btn, self.arm_btn, self.disarm_btn)
        self._accepted: dict[int, Any] = {id(h): h.value for h in self._inputs}
        self._lock = threading.Lock()
        self._faults = FaultTracker()
        self._link_feed = LinkFeed(self.app.recorder)  # link health -> lab data
        self.clock = time.monotonic  # what the panel's pacing reads (tests move it by hand)
        self._t0 = self.clock()
        self._samples: collections.deque = collections.deque(maxlen=HISTORY)
        self._pacer = PlotPacer(PLOT_HZ, visible=PLOT_VISIBLE)
        self._top = PLOT_MIN_TOP
        self._readout_text = HealthReadout()
        self._received = -1
        self._refreshed_at = 0.0
        self._fill_port = not default_port  # once: the path the loop reports (soft-arm pty)

        self.connect_btn.on_click(self._on_connect)
        self.disconnect_btn.on_click(self._on_disconnect)
        self.arm_btn.on_click(self._on_arm)
        self.disarm_btn.on_click(self._on_disarm)
        self.restart_btn.on_click(self._on_restart)
        self.port_list.on_update(self._on_port_choice)
        self.port_text.on_update(self._on_port_text)
        self.baud.on_update(self._on_baud)
        self.refresh()
        self._quit = threading.Event()
        self._idle = threading.Thread(target=self._idle_loop, name="hardware-panel", daemon=True)
        self._idle.start()

    # -- what the panel talks to -------------------------------------------------------------
    def controls(self) -> BridgeControls | None:
        """The loop's bridge controls (None: no serial link to manage)."""
        return self.app.services.bridge_controls

    def selected_port(self) -> str:
        """The port Connect uses: the typed path, else the picked device ("" for none)."""
        text = str(self.port_text.value).strip()
        if text or self.port_list.value == OTHER:
            return text
        return str(self.port_list.value)

    # -- callbacks (thin: enqueue) -----------------------------------------------------------
    def _tell(self, event: Any, message: str) -> None:
        client = client_of(event)
        if client is not None:
            client.add_notification("Hardware", message, color="orange", auto_close_seconds=6.0)

    def _enqueue(self, event: Any, what: str,
                 verb: Callable[[BridgeControls], None]) -> None:
        ctl = self.controls()
        if ctl is None:
            self._tell(event, no_controls_text(self.kind, self.owner).replace("**", ""))
            return
        verb(ctl)
        self.app.recorder.action(f"hardware: {what}", client_of(event))

    @operator_only(action="connect the hardware")
    def _on_connect(self, event: viser.GuiEvent) -> None:
        port = self.selected_port()
        if not port and self.controls() is not None:
            self._tell(event, "Type the controller's port first (a device path such as "
                              "/dev/ttyACM0, or a pyserial URL).")
            return
        baud = int(self.baud.value)
        self._enqueue(event, f"connect {port} at {baud} baud",
                      lambda ctl: ctl.connect(port, baud))

    @operator_only(action="disconnect the hardware")
    def _on_disconnect(self, event: viser.GuiEvent) -> None:
        self._enqueue(event, "disconnect", lambda ctl: ctl.disconnect())

    @operator_only(action="arm the device")
    def _on_arm(self, event: viser.GuiEvent) -> None:
        self._enqueue(event, "arm the device", lambda ctl: ctl.arm())

    @operator_only(action="disarm the device")
    def _on_disarm(self, event: viser.GuiEvent) -> None:
        self._enqueue(event, "disarm the device", lambda ctl: ctl.disarm())

    @operator_only(action="restart the control loop")
    def _on_restart(self, event: viser.GuiEvent) -> None:
        client = client_of(event)
        if self.app.loop_header is None:
            self._tell(event, "This console has no control loop process to restart.")
            return
        if not self._restarting.acquire(blocking=False):
            self._tell(event, "The control loop is being restarted.")
            return
        threading.Thread(target=self._restart, args=(client,), name="loop-restart",
                         daemon=True).start()

    def _restart(self, client: Any) -> None:
        """Worker: the core ends motion and replaces the loop process (blocks seconds); tell
        everyone."""
        try:
            self.restart_btn.disabled = True
            self.app.core.restart_loop(client)
        except Exception as exc:  # noqa: BLE001 - say why, keep the button for another try
            log.exception("restarting the control loop failed")
            self.app.notify_all("Restart control loop", f"failed: {exc}", color="red")
        else:
            self.app.notify_all("Control loop restarted",
                                "A new control loop runs, disarmed: Arm to move the arm again.",
                                color="orange")
        finally:
            self.restart_btn.disabled = False
            self._restarting.release()

    @operator_only(action="change the serial port")
    def _on_port_choice(self, event: viser.GuiEvent) -> None:
        self._accepted[id(self.port_list)] = self.port_list.value
        if event.client is not None and self.port_list.value != OTHER:
            self.port_text.value = self.port_list.value  # Connect uses the text field

    @operator_only(action="change the serial port")
    def _on_port_text(self, event: viser.GuiEvent) -> None:
        self._accepted[id(self.port_text)] = self.port_text.value
        if event.client is not None and self.port_list.value not in (OTHER,
                                                                     self.port_text.value):
            self.port_list.value = OTHER  # typed something else than the picked device

    @operator_only(action="change the baud rate")
    def _on_baud(self, event: viser.GuiEvent) -> None:
        self._accepted[id(self.baud)] = self.baud.value

    def on_refused(self, event: Any) -> None:
        """A viewer changed the port or baud field: put the operator's value back for all."""
        target = target_of(event)
        for handle in self._inputs:  # the refused one of the fields put back
            if target is handle:
                handle.value = self._accepted[id(handle)]

    # -- display -----------------------------------------------------------------------------
    def on_state(self, state: ArmState) -> None:
        if self.clock() - self._refreshed_at >= 1.0 / REFRESH_HZ:
            self.refresh()

    def _idle_loop(self) -> None:
        period = 1.0 / REFRESH_HZ
        while not self._quit.wait(period) and not self.app.stopped:
            if self.clock() - self._refreshed_at < period:
                continue  # on_state is refreshing
            try:
                self.refresh()
            except Exception:  # a display hiccup must not end the thread
                log.debug("hardware panel refresh failed", exc_info=True)

    def refresh(self) -> None:
        """Show the newest health; notify each new fault once to every browser."""
        with self._lock:
            self._refreshed_at = self.clock()
            loop_header = self.app.loop_header
            self.restart_btn.visible = loop_header is not None and loop_header.needs_restart
            ctl = self.controls()
            h = None if ctl is None else ctl.health()
            # (viser sends a property only when its value changes)
            self.note.content = "" if ctl is not None else no_controls_text(self.kind, self.owner)
            self.note.visible = ctl is None
            self.readout.visible = ctl is not None
            self.plot.visible = ctl is not None and len(self._samples) >= 2  # once there is data
            for handle in self._inputs:
                handle.disabled = ctl is None
            state = h.state if h is not None else "unconfigured"
            if self.app.robot.kind == "delta":  # the soft arm's Control panel tells its link
                link = h if ctl is not None else extensible_link_health(self.app)  # mock
                shown = self.app.loop_header or self.app.header  # (checks the view's age)
                shown.show("link", *header_link(self.kind, link))
            self.connect_btn.disabled = ctl is None
            self.disconnect_btn.disabled = ctl is None or state == "unconfigured"
            self.arm_btn.disabled = ctl is None or state != "inactive"
            self.disarm_btn.disabled = ctl is None or state != "active"
            if ctl is None:
                return
            # (a steady link's text stays the same: viewers are sent nothing)
            self.readout.content = self._readout_text.text(self.clock(), h)
            if h is None:
                return
            if self._fill_port and h.port:
                self._fill_port = False
                if not str(self.port_text.value).strip():
                    self.port_text.value = h.port  # the port the loop actually uses
            self._plot(h)
            self._link_feed.on_health(self.kind or "device", h)
            new = self._faults.update(h)
        if new:
            body = "; ".join(new) + " — the arm is not commanded until the operator " \
                                    "reconnects and arms again."
            self.app.notify_all("Hardware fault", body, color="red")
            self.app.recorder.action(f"hardware fault: {'; '.join(new)}", None)

    @staticmethod
    def _scales(top: float) -> dict[str, Any]:
        return {"x": uplot.Scale(time=False), "ms": uplot.Scale(auto=False, range=(0.0, top))}

    def _plot(self, h: LinkHealth) -> None:
        if h.rtt_ms_p50 is None or h.received == self._received:
            return  # no new telemetry: do not stretch the plot with stale numbers
        self._received = h.received
        p99 = h.rtt_ms_p99 if h.rtt_ms_p99 is not None else float("nan")
        now = self.clock()
        self._samples.append((now - self._t0, h.rtt_ms_p50, p99))
        if len(self._samples) < 2:
            return  # the plot is hidden until it has a line to show
        data = np.asarray(self._samples, dtype=float)
        top = axis_top(data[:, 1:], PLOT_MIN_TOP)
        # A steady link's plot pauses; a jittering one is redrawn at most PLOT_HZ, and only for
        # moves a person could tell from jitter on the axis.
        if not self._pacer.due(now, (h.rtt_ms_p50, p99), top):
            return
        if top != self._top:
            self._top = top
            self.plot.scales = self._scales(top)
        self.plot.data = thin((data[:, 0], data[:, 1], data[:, 2]), PLOT_POINTS)

    def close(self) -> None:
        self._quit.set()
        if self._idle is not threading.current_thread():
            self._idle.join(2.0)
        super().close()
