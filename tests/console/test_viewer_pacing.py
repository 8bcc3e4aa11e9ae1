"""A still console costs its viewers ~nothing (issue 15): live plots and text are re-sent only
when a person could see them change. Counted as a websocket viewer receives them (the Hardware
panel's round-trip plot and readout), or on the plot handles (the Control panel's plots and
kappa table), on clocks the tests move by hand."""

from __future__ import annotations

import dataclasses
import itertools
import time
from typing import Any

import numpy as np
import pytest
import viser

from console.panels.soft_arm import control_plots as cp
from console.panels.common import hardware as hwp
from console.core.hardware_attachment import HardwareAttachment
from console.panels.soft_arm.control import ControlPanel
from console.panels.common.plot_data import PlotPacer, axis_top
from console.web import install
from core.robots import load
from hw_bridge.interface import LinkHealth
from fakes import FakeClock
from tests.ws_client import RawClient

MARKS = itertools.count()
EXT = load("extensible")
SOFT = load("soft-arm")


# -- the pacer ----------------------------------------------------------------------------------

def test_axis_top_is_a_1_2_5_step_above_the_values_with_headroom() -> None:
    assert axis_top([0.2, 0.4], 1.0) == 1.0  # the minimum
    assert axis_top([1.5, 3.0], 1.0) == 5.0  # 3.3 -> 5
    assert axis_top([1.5, 1.7], 1.0) == 2.0  # 1.87 -> 2
    assert axis_top([9.5, np.nan], 1.0) == 20.0  # 10.45 -> 20; NaN ignored
    assert axis_top([np.nan], 20.0) == 20.0
    for v in np.random.default_rng(0).uniform(0.1, 500.0, 200):
        top = axis_top([v], 0.01)
        assert 1.1 * v <= top < 2.5 * 1.1 * v + 1e-9  # holds it, never more than a step above


def test_pacer_sends_a_visible_change_at_its_rate_and_pauses_while_nothing_changes() -> None:
    pacer = PlotPacer(max_hz=0.5, visible=0.03)
    t = 0.0
    assert pacer.due(t, [1.5, 3.0], 5.0)  # the first draw
    rng = np.random.default_rng(1)
    sent = 0
    for _ in range(100):  # 25 s of jitter below 3 % of a 5 ms axis (0.15 ms)
        t += 0.25
        sent += pacer.due(t, [1.5, 3.0] + rng.uniform(-0.1, 0.1, 2), 5.0)
    assert sent == 0
    t += 0.25
    assert pacer.due(t, [1.5, 3.5], 5.0)  # 0.5 ms: visible, sent at once
    t += 0.25
    assert not pacer.due(t, [1.5, 4.5], 5.0)  # visible, but within 1 / max_hz of the last
    t += 2.0
    assert pacer.due(t, [1.5, 4.5], 5.0)  # ... so it waits for the next slot
    assert not pacer.due(t + 2.5, [1.5, 4.5], 5.0)
    assert pacer.due(t + 2.5, [1.5, 4.5], 10.0)  # the axis changed: a redraw
    assert not any(pacer.due(t + 2.5 + k, [1.5, 4.5], 10.0)  # nothing new: paused, however
                   for k in (30.0, 300.0, 3000.0))               # long
    assert pacer.due(t + 40.0, [1.5, np.nan], 10.0)  # a value appeared / went: visible
    with pytest.raises(ValueError):
        PlotPacer(max_hz=0.0)


# -- the Hardware panel, as a websocket viewer receives it --------------------------------------

HEALTH = LinkHealth(state="active", port="/dev/pts/9", fault=None, armed=True,
                    watchdog_tripped=False, estop=False, rtt_ms_p50=1.5, rtt_ms_p99=3.0,
                    rtt_ms_last=1.4, sent=10, received=10, lost=0, crc_errors=0,
                    bad_frames=0, device_rx_errors=0, state_age_ms=4.0)


class Controls:
    """The Hardware panel's bridge controls: only ``health()`` is read here."""

    def __init__(self) -> None:
        self.h = HEALTH

    def health(self) -> Any:
        return self.h


def updates(client: RawClient, handle: Any, prop: str) -> list[Any]:
    """Every value of ``prop`` the viewer received for the widget ``handle``."""
    uuid = handle._impl.uuid
    return [m["updates"][prop] for m in client.received(
        "GuiUpdateMessage", lambda m: m["uuid"] == uuid and prop in m["updates"])]


def settle(client: RawClient, marker: Any) -> None:
    """Wait until the viewer received everything queued so far (a marker sent last): viser
    drops a queued update to a property that a newer one overwrites before it is sent, so a
    test counting updates lets each one arrive."""
    text = f"marker {next(MARKS)}"
    marker.content = text
    deadline = time.monotonic() + 20.0
    while text not in updates(client, marker, "_markdown"):
        assert time.monotonic() < deadline, "the viewer never received the marker"
        time.sleep(0.005)


@pytest.fixture
def hardware(server) -> Any:
    from fakes import console_app

    install()
    controls = Controls()
    app = console_app(EXT, server, panels=(), bridge_controls=controls,
                      hardware=HardwareAttachment("test", kind="emulator",
                                                      port_path="/dev/pts/9", baud=1_000_000))
    panel = app.add_panel(hwp.HardwarePanel)
    panel._quit.set()  # the test refreshes by hand
    panel._idle.join(2.0)
    panel.clock = clock = FakeClock(float(int(time.monotonic()) + 1000))  # after what build() read
    marker = server.gui.add_markdown("")
    client = RawClient(server)
    try:
        yield panel, controls, clock, client, marker
    finally:
        client.ws.close()
        panel.close()


def test_rtt_jitter_a_viewer_could_not_see_sends_no_plot_and_a_visible_change_does(
        hardware) -> None:
    panel, controls, clock, client, marker = hardware
    rng = np.random.default_rng(2)

    def run(seconds: float, p99: float, jitter: float = 0.04) -> None:
        for _ in range(int(seconds * hwp.REFRESH_HZ)):
            clock.t += 1.0 / hwp.REFRESH_HZ
            h = controls.h
            controls.h = dataclasses.replace(
                h, received=h.received + 25, sent=h.sent + 25,
                rtt_ms_p50=1.5 + rng.uniform(-jitter, jitter),
                rtt_ms_p99=p99 + rng.uniform(-jitter, jitter))
            panel.refresh()
            settle(client, marker)

    run(1.0, 3.0)  # the first samples: the plot appears once
    settle(client, marker)
    client.clear()
    run(25.0, 3.0, jitter=0.2)  # 25 s of a steady link whose round trips jitter by +-0.2 ms
    settle(client, marker)
    assert updates(client, panel.plot, "data") == []  # 4 % of a 0..5 ms axis: jitter
    run(0.25, 4.2, jitter=0.0)  # p99 up by 1.2 ms: a viewer sees it
    settle(client, marker)
    data = updates(client, panel.plot, "data")
    assert len(data) == 1 and len(data[0]) == 3  # t, p50, p99
    client.clear()
    run(60.0, 4.2, jitter=0.0)  # a minute of the same: the plot pauses
    settle(client, marker)
    assert updates(client, panel.plot, "data") == []


def test_a_steady_links_readout_stays_put_and_news_and_rate_changes_show_at_once(
        hardware) -> None:
    """The readout's counters became rates and its round trips steady figures: a steady
    100 Hz link whose round trips jitter sends viewers nothing after the rates are known; a
    lost demand, a stalled reply stream and a slower round trip each show at once."""
    panel, controls, clock, client, marker = hardware
    rng = np.random.default_rng(5)

    def run(seconds: float, received_per_read: int = 25, p99: float = 3.0) -> list[str]:
        client.clear()
        for _ in range(int(seconds * hwp.REFRESH_HZ)):
            clock.t += 1.0 / hwp.REFRESH_HZ
            h = controls.h
            controls.h = dataclasses.replace(
                h, sent=h.sent + 25 + int(rng.integers(-1, 2)),
                received=h.received + received_per_read,
                rtt_ms_p50=1.5 + rng.uniform(-0.2, 0.2), rtt_ms_p99=p99 + rng.uniform(-0.3, 0.3),
                state_age_ms=float(rng.uniform(0.0, 12.0)))
            panel.refresh()
            settle(client, marker)
        settle(client, marker)
        return updates(client, panel.readout, "_markdown")

    shown = run(hwp.RATE_WINDOW_S + 1.0)  # the rates become known
    assert "sent 100/s" in shown[-1] and "received 100/s" in shown[-1], shown[-1]
    assert run(30.0) == []  # 30 s of a steady link: nothing
    clock.t += 0.25
    controls.h = dataclasses.replace(controls.h, lost=1)  # a lost demand: shown at once
    panel.refresh()
    settle(client, marker)
    shown = updates(client, panel.readout, "_markdown")
    assert len(shown) == 1 and "lost 1" in shown[0]
    shown = run(1.0, received_per_read=0)  # replies stop: shown within a second ...
    assert shown and "received 100/s" not in shown[-1], shown
    shown = run(hwp.RATE_WINDOW_S, received_per_read=0)  # ... and 0 once the window passed
    assert shown and "received 0/s" in shown[-1], shown
    shown = run(3.0, p99=6.0)  # the round trip doubles
    assert shown and ("p99 6." in shown[-1] or "p99 5." in shown[-1]), shown


# -- the Control panel's plots and kappa table (soft arm) ---------------------------------------

class FakePlot:
    """A uPlot handle that counts what is assigned to it."""

    def __init__(self) -> None:
        self.sent: list[tuple[str, Any]] = []

    def __setattr__(self, name: str, value: Any) -> None:
        if name != "sent":
            self.sent.append((name, value))
        object.__setattr__(self, name, value)

    def data_sent(self) -> int:
        return sum(1 for name, _ in self.sent if name == "data")


class FakeGui:
    def add_uplot(self, **kwargs: Any) -> FakePlot:
        return FakePlot()


def test_error_plot_ignores_a_still_arms_noise_and_follows_a_move() -> None:
    plots = cp.ControlPlots(FakeGui(), 6, 300)
    rng = np.random.default_rng(3)
    ref = np.array([3.0, -2.0, 1.0, 0.0, 4.0, -1.0])
    t = 0.0

    def run(seconds: float, ref: np.ndarray, phase: str = "idle") -> None:
        nonlocal t
        for i in range(int(seconds * 30)):
            t += 1 / 30
            meas = ref + 0.35 * rng.standard_normal(6)  # the simulator's noise (1/m rms)
            plots.append(t, ref, meas, phase, 10.0 + 0.3 * rng.standard_normal(),
                         0.4 + 0.05 * rng.standard_normal())
            if i % 8 == 0:  # the panel draws at ~4 Hz
                plots.draw(t)

    run(1.0, ref)
    err0, loop0 = plots.error_plot.data_sent(), plots.loop_plot.data_sent()
    assert err0 == 1 and loop0 == 1
    run(25.0, ref)  # a still arm: noise only
    assert plots.error_plot.data_sent() == err0
    assert plots.loop_plot.data_sent() == loop0  # +-0.3 ms jitter on a 0..20 ms axis
    moved = ref + np.array([0, 0, 2.0, 0, 0, 0])
    run(1.0, moved)  # a target moves by 2 1/m (drawn at once; its measurement follows)
    moves = plots.error_plot.data_sent() - err0
    assert 1 <= moves <= cp.ERROR_PLOT_HZ * 1.0
    run(60.0, moved)  # still again: the plots pause
    assert plots.error_plot.data_sent() == err0 + moves
    assert plots.loop_plot.data_sent() == loop0
    run(1.0, moved, phase="grasp")  # a task starts (its grey band), nothing moves yet
    assert plots.error_plot.data_sent() == err0 + moves + 1
    run(1.0, moved, phase="released")  # ... and ends
    assert plots.error_plot.data_sent() == err0 + moves + 2


def test_kappa_table_follows_the_drawn_arm_not_the_noise() -> None:
    from test_control_console import FakeControl, fake_view

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    from fakes import console_app

    app = console_app(SOFT, server, panels=(), soft_control=FakeControl())
    panel = app.add_panel(ControlPanel)
    panel._pump_stop.set()  # the test drives the pump itself
    panel._pump.join(2.0)
    try:
        rng = np.random.default_rng(4)
        meas0 = np.array([0.5, -1.25, 2.0, 0.0, 3.333, -6.7])
        shown: list[str] = []

        def pump(meas: np.ndarray, **kw: Any) -> None:  # (armed: the 3D view draws it)
            panel.ctl.view = fake_view(kappa_meas=tuple(meas), armed=True, **kw)
            panel._plot_at = 0.0
            panel._table_at = 0.0  # as if the table's rate allowed a redraw each time
            panel._pump_once()
            if not shown or panel.kappa_md.content != shown[-1]:
                shown.append(panel.kappa_md.content)

        for _ in range(3):
            pump(meas0)
        first = len(shown)
        for _ in range(30):  # noise: the drawn arm did not move (no frame sent)
            pump(meas0 + 0.3 * rng.standard_normal(6))
        assert len(shown) == first
        app.view.frames_sent += 1  # the 3D view drew a move: the table follows it
        pump(meas0 + 2.0)
        assert len(shown) == first + 1 and 'kappa-meas-0">+2.50<' in shown[-1]
    finally:
        panel.close()
        server.stop()


# -- the arm view's dead band while the arm moves -------------------------------------------------

def test_a_slow_steady_move_is_drawn_every_frame_and_noise_still_is_not(server, monkeypatch
                                                                        ) -> None:
    """A grasp-and-place approach moves the soft arm's points by a few mm/s: inside the still
    arm's 0.5 mm band for several frames, so it was drawn at ~10 frames/s. Moving steadily, the
    band is 0.1 mm: every frame of a 6 mm/s move (0.2 mm per frame at 30 Hz) is drawn once the
    steadiness has been measured over ``moving_steps`` frames; noise is never steady."""
    import console.scene.arm_view as arm_view
    from console.scene.arm_view_factory import make_arm_view
    from console.scene.dead_band import DeadBand
    from console.core.model import model_for

    clock = FakeClock()
    monkeypatch.setattr(arm_view.time, "monotonic", clock)
    view = make_arm_view(server.scene, model_for(SOFT))
    band = view.dead_band
    assert band.moving_position < band.position and band.moving_angle < band.angle
    q = np.array([8.0, -5.0, 3.0, 0.0, 2.0, -1.0])
    direction = np.array([1.0, -1.0, 1.0, 1.0, -1.0, 1.0])
    tip = lambda k: view.frames(k)[-1, :3, 3]  # noqa: E731
    per_unit = np.linalg.norm(tip(q + 1e-3 * direction) - tip(q)) / 1e-3
    step = 2e-4 / per_unit * direction  # the tip moves 0.2 mm per frame
    clock.t += 5.0
    assert view.update(q)
    start = view.frames_sent
    for k in range(1, 91):  # 3 s at 30 frames/s
        clock.t += 1 / 30
        view.update(q + k * step)
        moved_from_sent = np.linalg.norm(tip(q + k * step) - view.frames(view._sent_q)[-1, :3, 3])
        assert moved_from_sent <= band.position + 1e-9  # never more than the wide band behind
    sent = view.frames_sent - start
    assert sent >= 90 - band.moving_steps  # every frame once it is known to move
    assert not band.moved(view.frames(q), view.frames(q + step))  # one step: inside the band
    # Noise of the same size per frame, never steady: held by the wide band, averaged.
    rng = np.random.default_rng(5)
    end = q + 90 * step
    clock.t += 5.0
    view.update(end)
    start = view.frames_sent
    for _ in range(300):  # 10 s
        clock.t += 1 / 30
        view.update(end + 2.0 * rng.standard_normal(6) * np.abs(step))
    assert view.frames_sent - start <= 2


def test_the_pump_reports_each_measurement_once() -> None:
    """A view pumped again (the publisher late) is not reported again: the same state twice
    reads to the arm view as an arm that stopped exactly there, which drew a still arm's noise."""
    from test_control_console import FakeControl, fake_view

    from fakes import console_app

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    app = console_app(SOFT, server, panels=(), soft_control=FakeControl(),
                      mirror_commands=False)
    panel = app.add_panel(ControlPanel)
    panel._pump_stop.set()  # the test drives the pump itself
    panel._pump.join(2.0)
    try:
        seqs = []
        for k in range(3):
            panel.ctl.view = fake_view(armed=True, kappa_meas=(0.5 + k, -1.0, 2.0, 0.0, 3.0, -6.0))
            for _ in range(3):  # pumped three times before the next view arrives
                panel._pump_once()
                seqs.append(app.store.display.seq)
        assert len(set(seqs)) == 3 and seqs[0] == seqs[2] and seqs[3] == seqs[5]
        np.testing.assert_allclose(app.store.display.q, (2.5, -1.0, 2.0, 0.0, 3.0, -6.0))
        assert app.store.display.source == "control"
    finally:
        panel.close()
        server.stop()
