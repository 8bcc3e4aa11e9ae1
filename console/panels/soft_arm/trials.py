"""Trials panel (soft arm): run the paper's grasp-and-place experiment headless, with progress.

*Run trials* starts a batch (spots A-E of :func:`core.control.trials.paper_locations` x repeats,
or one custom spot) on the simulated clock in a spawned worker process
(:func:`core.control.trials.run_trials` through this panel's one-process pool), so the
console's 100 Hz loop and render thread keep their interpreter. A progress bar follows the finished trials; the results table lists each
trial (spot, success, failure reason, approach and return times) and the total.

*Side* runs the spots as given (the paper's left quadrant), their mirror images across the
arm's base line (A'-E', the right finger of a two-finger gripper, :mod:`core.planning.sides`)
or both; a small table with a bar per side shows the success rate of each side
(:func:`sides_html`).
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import threading
from typing import Any

import viser

from console.panels.common.base import Panel, operator_only
from core.control.trials import TrialResult, paper_locations, per_side, run_trials, sided_objects
from core.units import MM_PER_M
from hw_bridge.parent_watch import pool_initializer

SPOTS = ("A-E (paper)", "custom")
SIDES = {"Left (paper)": "left", "Right (mirrored)": "right", "Both": "both"}
BAR_COLORS = {"left": "#1f5fd6", "right": "#d98c1f"}


def sides_html(results: list[TrialResult]) -> str:
    """Success per side: a table (side, successes / trials, rate) and one bar per side."""
    counts = per_side(results)
    if not counts:
        return ""
    rows, bars = [], []
    for k, (side, d) in enumerate(counts.items()):
        rate = d["successes"] / d["trials"]
        rows.append(f"<tr data-side='{side}'><td>{side}</td><td>{d['successes']}/{d['trials']}"
                    f"</td><td>{rate:.0%}</td></tr>")
        y = 4 + 22 * k
        bars.append(f"<text x='0' y='{y + 13}' font-size='11'>{side}</text>"
                    f"<rect x='40' y='{y}' width='160' height='16' fill='#eee'/>"
                    f"<rect x='40' y='{y}' width='{160 * rate:.1f}' height='16' "
                    f"fill='{BAR_COLORS[side]}'/><text x='206' y='{y + 13}' font-size='11'>"
                    f"{rate:.0%}</text>")
    height = 8 + 22 * len(counts)
    return ("<table class='trial-sides'><tr><th>side</th><th>successes</th><th>rate</th></tr>"
            + "".join(rows) + "</table>"
            + f"<svg xmlns='http://www.w3.org/2000/svg' width='240' height='{height}' "
              f"role='img' aria-label='success rate per side'>" + "".join(bars) + "</svg>")


def results_markdown(results: list[TrialResult], loop: dict | None = None) -> str:
    """Markdown table of trial results."""
    if not results:
        return "<small>no results yet</small>"
    rows = ["| # | spot | ok | approach (s) | return (s) | failure |",
            "|---|---|---|---|---|---|"]
    for i, r in enumerate(results, 1):
        rows.append(f"| {i} | {r.label} | {'✓' if r.success else '✗'} | {r.approach_s:.1f} | "
                    f"{r.return_s:.1f} | {r.failure or ''} |")
    ok = sum(r.success for r in results)
    tail = f"\n\n**{ok}/{len(results)} successes**"
    if loop:
        tail += (f" · simulated {loop['sim_s']:.0f} s in {loop['wall_s']:.1f} s "
                 f"({loop['speedup_vs_real_time']}x real time)")
    return "\n".join(rows) + tail


class TrialsPanel(Panel):
    """Batch of headless grasp-and-place trials with a progress bar and a results table."""

    title = "Trials"
    tab = "Experiments"
    order = 60.0
    kinds = ("planar",)

    def build(self) -> None:
        gui = self.gui
        r0 = self.app.robot.capture.nominal_object_radius
        self.spots = gui.add_dropdown("Spots", SPOTS, initial_value=SPOTS[0])
        self.x = gui.add_number("Custom x (mm)", -160.0, step=5.0)
        self.y = gui.add_number("Custom y (mm)", 280.0, step=5.0)
        self.r = gui.add_number("Object r (mm)", round(r0 * MM_PER_M, 3), min=5.0, max=50.0,
                                step=0.5)
        two = "right" in self.app.robot.gripper.sides
        self.side = gui.add_dropdown("Side", tuple(SIDES) if two else tuple(SIDES)[:1],
                                     initial_value="Left (paper)",
                                     disabled=not two)
        self.repeats = gui.add_slider("Repeats", min=1, max=10, step=1, initial_value=5)
        self.seed = gui.add_number("Seed", 0, step=1)
        self.run_btn = gui.add_button("Run trials", icon=viser.Icon.PLAYER_PLAY)
        self.progress = gui.add_progress_bar(0.0, visible=False)
        self.status = gui.add_markdown("<small>idle</small>")
        self.sides = gui.add_html("")
        self.table = gui.add_markdown(results_markdown([]))
        self.run_btn.on_click(operator_only(lambda e: self._start(), panel=self, action="run trials"))
        self._thread: threading.Thread | None = None
        self.results: list[TrialResult] = []

    def objects(self) -> list[tuple[str, tuple[float, float, float]]]:
        """The batch's objects (label, (x, y, r)) in metres; the fields are in mm."""
        r = float(self.r.value) / MM_PER_M
        if self.spots.value == SPOTS[0]:
            given = [(k, (x, y, r)) for k, (x, y) in paper_locations().items()]
        else:
            given = [("custom", (float(self.x.value) / MM_PER_M, float(self.y.value) / MM_PER_M,
                                 r))]
        return sided_objects(self.app.robot, given, SIDES[str(self.side.value)])

    def _start(self) -> None:
        if self._thread is not None and self._thread.is_alive():
            return
        objects, repeats, seed = self.objects(), int(self.repeats.value), int(self.seed.value)
        self.run_btn.disabled = True
        self.progress.value, self.progress.visible = 0.0, True
        self.sides.content = ""
        self.status.content = f"<small>running {len(objects) * repeats} trials…</small>"
        self._thread = threading.Thread(target=self._run, args=(objects, repeats, seed),
                                        name="trials-batch", daemon=True)
        self._thread.start()

    def _run(self, objects: list, repeats: int, seed: int) -> None:
        import time
        from core.control.trials import summary
        done: list[TrialResult] = []

        def progress(k: int, n: int, r: TrialResult) -> None:
            done.append(r)
            self.progress.value = 100.0 * k / n
            self.status.content = f"<small>{k}/{n} trials done</small>"
            self.table.content = results_markdown(sorted(done, key=lambda x: x.seed))
            self.sides.content = sides_html(done)

        t0 = time.perf_counter()
        try:
            src = str(self.app.robot.source)
            with cf.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"),
                                        initializer=pool_initializer) as pool:
                self.results = run_trials(src, objects, repeats, seed, progress=progress,
                                          map_fn=pool.map)
            loop: dict[str, Any] = summary(self.results, time.perf_counter() - t0, 1)
            self.table.content = results_markdown(self.results, loop)
            self.sides.content = sides_html(self.results)
            self.status.content = "<small>done</small>"
        except Exception as exc:  # report, never kill the console
            self.status.content = f"**Trials failed:** {exc}"
        finally:
            self.run_btn.disabled = False
            self.progress.visible = False
