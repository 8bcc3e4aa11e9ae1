"""A new Repeatability run starts from an empty table: seen in a walk through the console, a run
after one that could not start ("open loop: not started: … disarmed (Arm to command the arm)")
showed that old reason under "Running open loop…" until its first move was measured."""

from __future__ import annotations

from typing import Any

from test_repeatability_compare import POINT, SlippingRunner, panel_with

from console.panels.extensible.repeatability import RunRequest


def test_a_new_run_does_not_show_the_last_runs_reason_while_it_moves(server: Any) -> None:
    tables: list[str] = []
    panel: list[Any] = []
    fake = SlippingRunner(on_move=lambda n: tables.append(panel[0].table.content))
    panel.append(panel_with(server, fake))
    p = panel[0]
    stale = RunRequest(POINT, 2, p.app.core.stop_generation)
    p.app.stop_motion("test")  # the first run ends before it moves, with a reason
    p._run(stale)
    assert 'data-state="stopped"' in p.table.content and "rep-message" in p.table.content
    p._run(RunRequest(POINT, 2, p.app.core.stop_generation))
    first = tables[0]  # what the table showed while the new run's first move ran
    assert 'data-state="running"' in first and "rep-message" not in first, first
    assert 'data-testid="rep-open-moves">0/2<' in first
    assert 'data-state="done"' in p.table.content
    p.close()
