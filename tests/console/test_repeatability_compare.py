"""The Repeatability panel's comparison (issue #17.4): one click runs N moves open loop, then N
closed loop, against a fake runner whose racks slip; both rows of the table are filled from what
the fake measured, the click only enqueues, and STOP queues no further move."""

from __future__ import annotations

import re
import threading
from typing import Any

import numpy as np
import pytest

from console.core.access import AccessControl
from console.panels.extensible.repeatability import TIP_SAMPLES, RepeatabilityPanel, run_comparison
from console.panels.extensible.repeatability_view import error_plot_svg
from core.kinematics import delta as dk
from core.kinematics.delta_ik import solve_tip_ik
from core.robots import load
from hw_bridge.extensible_jobs import JobResult
import ws_client
from fakes import FakeClient, console_app, user

EXT = load("extensible")
HOME = dk.robot_rack_lengths(EXT, np.zeros((EXT.n_segments, 3)))
POINT = dk.tip_position(EXT, np.array([[0.02, -0.01, 0.08], [-0.01, 0.015, 0.05]]))


def tip_of(lengths: np.ndarray) -> np.ndarray:
    return dk.tip_position(EXT, dk.delta_from_actuators(lengths, EXT.phi, EXT.L0))


class SlippingRunner:
    """Runner and tip sensor in one: every move loses a random fraction (slip +- jitter, per
    rack) of its rack travel; retracting re-homes the racks on their stops. It records every
    tip it measured with the repetition it belongs to (a repetition starts with a retract)."""

    started = True
    failure = None
    view = None

    def __init__(self, slip: float = 0.2, jitter: float = 0.05, seed: int = 4,
                 stop_after: int | None = None, on_move: Any = None,
                 on_wait: Any = None) -> None:
        self.robot = EXT
        self.slip, self.jitter = slip, jitter
        self.rng = np.random.default_rng(seed)
        self.true = HOME.copy()
        self.cmd = HOME.copy()
        self.rep = 0
        self.jobs: dict[int, JobResult] = {}
        self.threads: set[str] = set()
        self.measured: list[tuple[int, np.ndarray]] = []
        self.stops = 0
        self.on_move = on_move
        self.on_wait = on_wait  # called with the job waited for, while it "runs"
        self.samples: set[int | None] = set()

    def start(self) -> SlippingRunner:
        return self

    def move_to(self, lengths: Any, label: str = "move") -> int:
        self.threads.add(threading.current_thread().name)
        goal = dk.limit_rack_lengths(EXT, np.asarray(lengths, float))
        if np.allclose(goal, HOME):
            self.true, self.rep = HOME.copy(), self.rep + 1
        else:
            s = self.rng.uniform(self.slip - self.jitter, self.slip + self.jitter, goal.shape)
            self.true = self.true + (1.0 - s) * (goal - self.cmd)
        self.cmd = goal
        job = len(self.jobs) + 1
        self.jobs[job] = JobResult(job, label, True, "", tip_of(goal), None, None)
        if self.on_move is not None:
            self.on_move(len(self.jobs))
        return job

    def wait(self, job: int, timeout: float | None = None) -> JobResult:
        if self.on_wait is not None:
            self.on_wait(job)
        return self.jobs[job]

    def stop(self) -> None:
        self.stops += 1

    def setpoint(self, seq: int, delta: Any) -> None:
        pass  # the console core forwards commands; this runner only runs moves

    def measure(self, samples: int | None = None) -> np.ndarray:
        self.samples.add(samples)
        t = tip_of(self.true)
        self.measured.append((self.rep, t))
        return t

    def reached(self, reps: range) -> np.ndarray:
        """The last tip measured in each of ``reps`` (what a move ended at)."""
        return np.array([[t for r, t in self.measured if r == rep][-1] for rep in reps])


def cell(content: str, testid: str) -> float:
    m = re.search(rf'data-testid="{testid}" data-mm="([-0-9.]+)"', content)
    assert m, (testid, content)
    return float(m.group(1))


def panel_with(server: Any, fake: SlippingRunner, sensor: bool = True) -> RepeatabilityPanel:
    app = console_app(EXT, server, panels=(), access=AccessControl("tok"),
                      extensible_runner=fake, tip_sensor=fake if sensor else None)
    panel = app.add_panel(RepeatabilityPanel)
    assert panel is not None
    for h, v in zip(panel.inputs, POINT * 1e3):
        h.value = float(v)
    return panel


def wait_for(fn: Any, timeout: float = 60.0) -> None:
    ws_client.wait_for(fn, timeout)


def test_one_click_fills_both_rows_from_the_runners_measured_tips(server) -> None:
    assert solve_tip_ik(EXT, POINT).reachable
    fake = SlippingRunner()
    panel = panel_with(server, fake)
    operator = FakeClient(12)
    panel.app.access.take(operator.client_id, "tok", name="Alice")
    panel.count.value = 4
    user(panel.run_btn, operator)
    assert threading.current_thread().name not in fake.threads  # the click only enqueued
    wait_for(lambda: 'data-state="done"' in panel.table.content)
    assert fake.threads == {"repeatability"}  # every move queued by the panel's worker
    assert fake.samples == {TIP_SAMPLES}  # both loops measure alike
    html = panel.table.content
    # Independent expectation: the tips the fake measured last in each repetition.
    for loop, reps in (("open", range(1, 5)), ("closed", range(5, 9))):
        tips = fake.reached(reps)
        errors = np.linalg.norm(tips - POINT, axis=1)
        spread = 0.5 * np.ptp(tips, axis=0)
        assert cell(html, f"rep-{loop}-mean") == pytest.approx(errors.mean() * 1e3, abs=1e-3)
        assert cell(html, f"rep-{loop}-spread") == pytest.approx(spread.mean() * 1e3, abs=1e-3)
        assert f'data-testid="rep-{loop}-moves">4/4<' in html
        dots = re.findall(rf'class="rep-dot-{loop}"[^>]*data-mm="([0-9.]+)"', panel.plot.content)
        assert np.allclose([float(d) for d in dots], errors * 1e3, atol=1e-3)
    # 20 % slip: the open loop misses by centimetres, the loop closed on the tip does not.
    assert cell(html, "rep-open-mean") > 10.0 and cell(html, "rep-closed-mean") < 1.5
    assert cell(html, "rep-closed-spread") < cell(html, "rep-open-spread")
    assert "Closed loop beats open loop" in html
    # The loop's cost: every move after the first in a closed-loop repetition is a correction.
    moves_out = sum(j.label == "closed loop" for j in fake.jobs.values())
    assert f"({(moves_out - 8) / 4:.1f} corrections per move)" in html and moves_out > 8
    assert cell(html, "rep-table-i-1") == 19.0 and cell(html, "rep-table-i-2") == 29.0
    assert panel.progress.value == 100.0
    panel.close()


def test_without_a_tip_sensor_only_the_open_loop_runs_on_the_encoders(server) -> None:
    fake = SlippingRunner()
    panel = panel_with(server, fake, sensor=False)
    operator = FakeClient(12)
    panel.app.access.take(operator.client_id, "tok", name="Alice")
    panel.count.value = 2
    user(panel.run_btn, operator)
    wait_for(lambda: 'data-state="done"' in panel.table.content)
    html = panel.table.content
    assert fake.measured == []  # nothing but the encoders measured
    assert "tips measured by the encoders" in html and "needs the tip sensor" in html
    assert cell(html, "rep-open-mean") < 0.1  # the encoders read their demand: no miss seen
    assert 'data-testid="rep-closed-mean"' not in html and "rep-verdict" not in html
    panel.close()


def test_stop_queues_no_further_move_and_skips_the_closed_loop(server) -> None:
    panel: list[RepeatabilityPanel] = []
    stopped_at: list[int] = []

    def stop_on_third(n: int) -> None:
        if n == 3:  # STOP from the header while the third move runs (the run waits for it)
            stopped_at.append(n)
            panel[0].app.stop_motion("test")
    # (STOP used to come from a thread started inside move_to, 0.3 s before the run went on:
    # the run's next move could take the gate's lock first, 2 in 9 runs)
    fake = SlippingRunner(on_wait=stop_on_third)
    panel.append(panel_with(server, fake))
    operator = FakeClient(12)
    panel[0].app.access.take(operator.client_id, "tok", name="Alice")
    user(panel[0].run_btn, operator)
    wait_for(lambda: 'data-state="stopped"' in panel[0].table.content)
    assert stopped_at == [3] and len(fake.jobs) == 3 and fake.stops >= 1
    html = panel[0].table.content
    assert "open loop: stopped" in html and 'data-testid="rep-open-moves">1/5<' in html
    assert 'data-testid="rep-closed-mean">—<' in html  # the closed loop never started
    assert "Stopped." in panel[0].status.content
    panel[0].close()


def test_run_comparison_refuses_an_unreachable_point_before_moving() -> None:
    fake = SlippingRunner()
    with pytest.raises(ValueError, match="unreachable"):
        run_comparison(fake, EXT, [0.0, 0.0, 3.0], 2, fake)  # type: ignore[arg-type]
    assert fake.jobs == {}


def test_error_plot_scales_to_the_largest_error() -> None:
    from console.panels.extensible.repeatability_view import Comparison, RepeatabilityResult
    tips = POINT + np.array([[0.0, 0.0, -0.012], [0.0, 0.0, -0.018]])
    c = Comparison(POINT, 2, 2, True, open=RepeatabilityResult(POINT, tips, 2))
    svg = error_plot_svg(c)
    assert svg.count('class="rep-dot-open"') == 2 and 'class="rep-dot-closed"' not in svg
    assert ">20</text>" in svg  # ticks 0..20 mm cover 18 mm


def test_a_request_older_than_the_newest_stop_moves_nothing(server) -> None:
    from console.panels.extensible.repeatability import RunRequest
    fake = SlippingRunner()
    panel = panel_with(server, fake)
    req = RunRequest(POINT, 2, panel.app.core.stop_generation)  # clicked ...
    panel.app.stop_motion("test")             # ... STOP before the worker took it
    panel._run(req)
    assert fake.jobs == {} and 'data-state="stopped"' in panel.table.content
    assert "Stopped." in panel.status.content
    panel.close()


def test_the_verdict_waits_for_all_n_moves_of_each_loop() -> None:
    """After 1 of 5 closed-loop moves its spread is 0 (one tip): no "beats ... (∞× smaller)"
    then, but "1 of 5"; with all 5 of each the verdict comes; a run that ended short has none."""
    from console.panels.extensible.repeatability_view import (Comparison, RepeatabilityResult,
                                                              comparison_html, verdict)
    rng = np.random.default_rng(3)
    point = np.asarray(POINT, dtype=float)
    opened = RepeatabilityResult(point, point + rng.normal(0, 2e-3, (5, 3)), 5)
    one = RepeatabilityResult(point, point[None] + 1e-4, 5, closed_loop=True)
    c = Comparison(point, 5, EXT.n_segments, True, open=opened, closed=one)
    line = verdict(c)
    assert "1 of 5 closed-loop moves" in line and "beats" not in line and "∞" not in line, line
    assert "1 of 5" in comparison_html(c)
    full = RepeatabilityResult(point, point + rng.normal(0, 1e-4, (5, 3)), 5, closed_loop=True)
    assert verdict(Comparison(point, 5, EXT.n_segments, True, open=opened, closed=full)
                   ).startswith("✔ Closed loop beats open loop")
    stopped = Comparison(point, 5, EXT.n_segments, True, open=opened, closed=one,
                         message="closed loop: stopped", finished=True)
    assert verdict(stopped).startswith("No verdict") and "1 of 5" in verdict(stopped)
