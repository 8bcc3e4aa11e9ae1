"""Issue 30.4: the Experiments tab's Design study panel opens a core.study results folder, shows
its table (mm units, the best variant per metric named) and a plot of a metric over a varied key,
and draws any variant's arm beside the console's own.

The study folders are made by core.study itself (``run_study``: its robot files, variant JSON,
CSV, Parquet and HTML): the soft arm's with hand-picked metric numbers in place of hours of
computation (its ``map_fn`` returns them), the extensible arm's computed for real. The
expectations are read back independently: the CSV with the ``csv`` module, the variants' robot
files with ``tomllib``, the best values as plain maxima, the ghost's geometry against the closed
form of a straight arm (n segments of length L: n L long).
"""

from __future__ import annotations

import csv
import math
import re
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from console.core.design_study import DesignStudies, StudyError
from console.panels.common.design_study import NONE_FOUND, DesignStudyPanel
from console.panels.common.study_table import column_unit, fmt_value
from console.scene.study_ghost import ROOT
from core.robots import load
from core.study import StudySpec, run_study
from tests.fakes import FakeClient, console_app, user

SOFT, EXT = load("soft-arm"), load("extensible")
THIN = "\u202f"
# Hand-picked metrics per segment count (SI, as core.study writes them): each metric has
# another best variant.
METRICS = {4: {"reachable_area_m2": 0.0412, "capture_area_m2": 0.00135,
               "grasp_place_success": 0.9, "grasp_place_trials": 10.0},
           6: {"reachable_area_m2": 0.0519, "capture_area_m2": 0.00121,
               "grasp_place_success": 0.8, "grasp_place_trials": 10.0},
           8: {"reachable_area_m2": 0.0487, "capture_area_m2": 0.00102,
               "grasp_place_success": 1.0, "grasp_place_trials": 10.0}}


def soft_study(out: Path, counts: tuple[int, ...] = (4, 6, 8), fail: int | None = None) -> Path:
    """A soft-arm study over segments.count written by core.study (metrics stubbed)."""
    def rows(fn: Any, jobs: list) -> list[dict[str, Any]]:
        out_rows = []
        for name, _, changes, *_ in jobs:  # (name, robot file, changes, spec[, text])
            n = changes["segments.count"]
            row = {"variant": name, **changes, "error": ""}
            if n == fail:
                row["error"] = "RuntimeError: planner gave up"
            else:
                row.update(METRICS[n])
            out_rows.append(row)
        return out_rows

    run_study("soft-arm", {"segments.count": list(counts)}, out, StudySpec(), map_fn=rows)
    return out


def pieces(mesh: Any) -> int:
    """How many separate pieces a mesh node holds: faces connected through vertices at the same
    place (a tube's caps have vertices of their own on its end rings)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    _, same = np.unique(np.round(np.asarray(mesh.vertices, dtype=float), 7), axis=0,
                        return_inverse=True)
    faces = same.ravel()[np.asarray(mesh.faces)]
    n = int(same.max()) + 1
    a = np.concatenate([faces[:, 0], faces[:, 1]])
    b = np.concatenate([faces[:, 1], faces[:, 2]])
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    return int(connected_components(graph, directed=False)[0])


def csv_rows(folder: Path) -> list[dict[str, str]]:
    with open(folder / "results.csv", newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture
def data(tmp_path: Path) -> Path:
    return tmp_path / "runs"


@pytest.fixture
def app(server: Any, data: Path) -> Any:
    soft_study(data / "studies" / "segments")
    return console_app(SOFT, server, data_dir=data, panels=(DesignStudyPanel,))


def opened(app: Any, client: FakeClient, folder: str = "studies/segments") -> DesignStudyPanel:
    panel = app.panel(DesignStudyPanel)
    user(panel.pick, client, folder)
    assert app.design_study.results is not None, client.notes
    return panel


def test_the_panel_lists_the_study_and_shows_every_variant_row(app: Any, data: Path) -> None:
    panel = app.panel(DesignStudyPanel)
    assert panel.pick.options == ("studies/segments",)
    panel = opened(app, FakeClient(1))
    expected = csv_rows(data / "studies" / "segments")
    assert len(expected) == 3
    lines = [line for line in panel.table.content.splitlines() if re.match(r"\| \d+ \|", line)]
    assert len(lines) == 3
    for i, (line, row) in enumerate(zip(lines, expected), 1):
        assert line.startswith(f"| {i} |")
        assert f"{i}: `{row['variant']}`" in panel.table.content  # the number names it
        # each metric in the unit its column names: m² shown as mm², whole
        mm2 = f"{float(row['reachable_area_m2']) * 1e6:,.0f}".replace(",", THIN)
        assert mm2 in line
        assert f"| {row['segments.count']} |" in line
    assert "reachable\\_area (mm²)" in panel.table.content.splitlines()[0]
    assert "studies/segments" in panel.status.content and "3 variants" in panel.status.content


def test_the_best_variant_per_metric_is_named(app: Any, data: Path) -> None:
    panel = opened(app, FakeClient(1))
    rows = csv_rows(data / "studies" / "segments")
    best_lines = [line for line in panel.table.content.splitlines() if "**Best" in line]
    for metric, header in (("reachable_area_m2", "reachable\\_area (mm²)"),
                           ("capture_area_m2", "capture\\_area (mm²)"),
                           ("grasp_place_success", "grasp\\_place\\_success")):
        top = max(rows, key=lambda r: float(r[metric]))["variant"]
        line = next(line for line in best_lines if f"Best {header}:" in line)
        assert f"`{top}`" in line, line
        others = [r["variant"] for r in rows if r["variant"] != top]
        assert not any(f"`{o}`" in line for o in others)
    # three metrics, three different winners (the numbers were picked so)
    assert len({line.split("`")[1] for line in best_lines}) == 3


def test_a_failed_variant_is_a_row_with_its_reason_and_no_best(server: Any, data: Path) -> None:
    soft_study(data / "studies" / "one-failed", fail=8)
    app = console_app(SOFT, server, data_dir=data, panels=(DesignStudyPanel,))
    panel = opened(app, FakeClient(1), "studies/one-failed")
    row8 = next(line for line in panel.table.content.splitlines() if line.startswith("| 3 |"))
    assert "planner gave up" in row8 and "**" not in row8
    best = [line for line in panel.table.content.splitlines() if "**Best" in line]
    assert best and not any("count=8" in line for line in best)
    # the plot leaves the failed variant's point out: its x has no number
    user(panel.metric, FakeClient(1), "reachable_area_m2")
    assert list(panel.plot.data[0]) == [4.0, 6.0]


def test_the_plot_is_the_chosen_column_over_the_varied_key(app: Any, data: Path) -> None:
    client = FakeClient(1)
    panel = opened(app, client)
    rows = csv_rows(data / "studies" / "segments")
    assert panel.over.value == "segments.count"
    for metric in ("capture_area_m2", "grasp_place_success", "reachable_area_m2"):
        user(panel.metric, client, metric)
        x, y = panel.plot.data
        scale = 1e6 if metric.endswith("_m2") else 1.0   # m² on screen as mm²
        assert list(x) == [float(r["segments.count"]) for r in rows]
        assert np.allclose(y, [float(r[metric]) * scale for r in rows], rtol=1e-12)
        assert panel.plot.visible
        assert [s["label"] for s in panel.plot.series] == ["segments.count",
                                                            column_unit(metric).header]


def test_show_variant_draws_its_arm_beside_the_console_s_and_hide_removes_it(
        app: Any, server: Any, data: Path) -> None:
    client = FakeClient(1)
    panel = opened(app, client)
    folder = data / "studies" / "segments"
    nodes = server.scene._handle_from_node_name
    assert not any(name.startswith(ROOT) for name in nodes)
    for row in csv_rows(folder):
        name = row["variant"]
        robot_file = tomllib.loads((folder / f"{name}.toml").read_text())
        n, length = robot_file["segments"]["count"], robot_file["segments"]["length"]
        user(panel.variant, client, name)
        user(panel.show_btn, client)
        assert f"{ROOT}/arm/segment_rings" in nodes and f"{ROOT}/arm/body" in nodes
        rings = nodes[f"{ROOT}/arm/segment_rings"]
        # one ring band (a closed tube of its own) at the end of each segment of the file
        assert pieces(rings) == n
        body = np.asarray(nodes[f"{ROOT}/arm/body"].vertices)
        # straight at rest along +y from the base: n segments of `length`, in the ghost's frame
        assert body[:, 1].max() - body[:, 1].min() == pytest.approx(n * length, abs=1e-6)
        root = nodes[ROOT]
        assert root.position[0] > 0.05 and abs(root.position[1]) < 1e-12   # beside, not on it
        assert rings.opacity is not None and rings.opacity < 1.0
        assert f"{n} segments" in panel.shown.content and name in panel.shown.content
        assert name in nodes[f"{ROOT}/label"].text
        assert not panel.hide_btn.disabled
    user(panel.hide_btn, client)
    assert not any(name.startswith(ROOT) for name in nodes)
    assert app.design_study.shown is None and panel.shown.content == ""
    assert panel.hide_btn.disabled
    assert client.notes == []


@pytest.mark.parametrize("typed, why", [
    ("/etc", "outside the console's data folder"),
    ("../..", "outside the console's data folder"),
    ("studies/nothing-here", "no such folder"),
    ("studies", "no results.parquet or results.csv"),
    ("studies/unfinished", "3 variants finished: the study has not ended"),
    ("studies/not-a-study", "no 'variant' column"),
    ("studies/outside-link", "outside the console's data folder"),
])
def test_a_bad_folder_is_refused_with_a_message_and_nothing_changes(
        app: Any, data: Path, tmp_path: Path, typed: str, why: str) -> None:
    (data / "studies" / "unfinished" / "variants").mkdir(parents=True)
    for k in range(3):
        (data / "studies" / "unfinished" / "variants" / f"v{k}.json").write_text("{}")
    (data / "studies" / "not-a-study").mkdir()
    (data / "studies" / "not-a-study" / "results.csv").write_text("a,b\n1,2\n")
    elsewhere = soft_study(tmp_path / "elsewhere", counts=(4,))
    (data / "studies" / "outside-link").symlink_to(elsewhere, target_is_directory=True)
    client = FakeClient(1)
    panel = opened(app, client)
    user(panel.variant, client, panel.variant.options[1])
    user(panel.show_btn, client)
    before = (app.design_study.results, app.design_study.shown, panel.table.content,
              panel.status.content, tuple(panel.plot.data[1]))
    user(panel.path, client, typed)
    user(panel.open_btn, client)
    assert client.notes and client.notes[-1][0] == "Cannot open the study"
    assert why in client.notes[-1][1], client.notes[-1][1]
    after = (app.design_study.results, app.design_study.shown, panel.table.content,
             panel.status.content, tuple(panel.plot.data[1]))
    assert after == before
    # the refused folders are no studies of the list either (the link is not followed)
    assert panel.pick.options == ("studies/segments",)
    user(panel.refresh_btn, client)
    assert set(panel.pick.options) == {"studies/not-a-study", "studies/segments"}


def test_a_typed_folder_opens_and_the_list_shows_it(server: Any, data: Path) -> None:
    soft_study(data / "studies" / "a", counts=(4,))
    soft_study(data / "studies" / "b", counts=(4, 6))
    app = console_app(SOFT, server, data_dir=data, panels=(DesignStudyPanel,))
    panel = app.panel(DesignStudyPanel)
    assert panel.pick.options == ("studies/a", "studies/b") and panel.pick.value == "studies/a"
    client = FakeClient(1)
    user(panel.path, client, str(data / "studies" / "b"))   # absolute, inside the data folder
    user(panel.open_btn, client)
    assert client.notes == []
    assert app.design_study.results.label == "studies/b" and panel.pick.value == "studies/b"
    assert panel.variant.options == app.design_study.results.variants


def test_an_empty_data_folder_says_so_and_opening_nothing_is_refused(server: Any,
                                                                    data: Path) -> None:
    app = console_app(EXT, server, data_dir=data, panels=(DesignStudyPanel,))
    panel = app.panel(DesignStudyPanel)
    assert panel.pick.options == (NONE_FOUND,)
    client = FakeClient(1)
    user(panel.open_btn, client)
    assert client.notes and "type a study folder" in client.notes[-1][1]
    assert app.design_study.results is None
    assert panel.show_btn.disabled and panel.metric.disabled


def test_a_real_extensible_study_in_the_console(server: Any, data: Path) -> None:
    """core.study computed for real (the extensible arm's workspace is quick), opened in the
    extensible console; its plot is the CSV's column in mm³ and Show variant draws the
    variant's racks."""
    folder = data / "studies" / "racks"
    run_study("extensible", {"segments.rack_max": [0.3, 0.41]}, folder, StudySpec())
    app = console_app(EXT, server, data_dir=data, panels=(DesignStudyPanel,))
    client = FakeClient(1)
    panel = opened(app, client, "studies/racks")
    rows = csv_rows(folder)
    user(panel.metric, client, "workspace_volume_m3")
    x, y = panel.plot.data
    assert list(x) == [float(r["segments.rack_max"]) for r in rows]
    assert np.allclose(y, [float(r["workspace_volume_m3"]) * 1e9 for r in rows])
    top = max(rows, key=lambda r: float(r["workspace_volume_m3"]))["variant"]
    line = next(line for line in panel.table.content.splitlines()
                if "Best workspace\\_volume (mm³)" in line)
    assert f"`{top}`" in line
    name = rows[0]["variant"]
    seg = tomllib.loads((folder / f"{name}.toml").read_text())["segments"]
    n = seg["count"]
    user(panel.variant, client, name)
    user(panel.show_btn, client)
    nodes = server.scene._handle_from_node_name
    assert pieces(nodes[f"{ROOT}/arm/platforms"]) == n + 1  # the base's and each segment end's
    # straight at rest, each rack at mid-range: the tip n mid-range lengths above the base
    mid = 0.5 * (seg["rack_min"] + seg["rack_max"])
    assert nodes[f"{ROOT}/arm/tip"].position[2] == pytest.approx(n * mid, abs=n * 1e-3)
    assert client.notes == []


def test_viewers_may_use_every_widget_of_the_panel(app: Any) -> None:
    panel = app.panel(DesignStudyPanel)
    widgets = [panel.pick, panel.refresh_btn, panel.path, panel.open_btn, panel.metric,
               panel.over, panel.variant, panel.show_btn, panel.hide_btn]
    assert all(app.guard.viewer_allowed(w) for w in widgets)
    viewer = FakeClient(7)   # no one holds control: every browser is a viewer
    assert not app.access.is_operator(viewer.client_id)
    opened(app, viewer)
    assert viewer.notes == []


def test_column_units_follow_the_suffix() -> None:
    cases = {"reachable_area_m2": ("reachable_area", "mm²", 1e6),
             "workspace_volume_m3": ("workspace_volume", "mm³", 1e9),
             "tip_error_m": ("tip_error", "mm", 1e3),
             "bend_rad": ("bend", "deg", 180 / math.pi),
             "tip_speed_m_s": ("tip_speed", "mm/s", 1e3),
             "repeatability_mm": ("repeatability", "mm", 1.0),
             "time_s": ("time", "s", 1.0),
             "grasp_place_success": ("grasp_place_success", "", 1.0),
             "segments.length": ("segments.length", "", 1.0)}
    for column, (name, unit, scale) in cases.items():
        u = column_unit(column)
        assert (u.name, u.unit) == (name, unit) and u.scale == pytest.approx(scale)
    assert fmt_value("tip_error_m", 0.0123) == "12.3"
    assert fmt_value("tip_error_m", -0.00001) == "0.0"          # never "-0.0"
    assert fmt_value("bend_rad", math.pi / 2) == "90.0"
    assert fmt_value("reachable_area_m2", 0.0519) == f"51{THIN}900"
    assert fmt_value("segments.count", 6) == "6"


def test_the_studies_read_parquet_first_and_csv_alike(data: Path) -> None:
    folder = soft_study(data / "studies" / "segments")
    studies = DesignStudies(data)
    from_parquet = studies.open("studies/segments")
    assert from_parquet.source == "results.parquet"
    (folder / "results.parquet").unlink()
    from_csv = studies.open(str(folder))   # an absolute path inside the data folder
    assert from_csv.source == "results.csv"
    assert from_csv.label == from_parquet.label == "studies/segments"
    assert from_csv.rows == from_parquet.rows and from_csv.best == from_parquet.best
    assert from_csv.keys == ("segments.count",)
    assert set(from_csv.metrics) >= {"reachable_area_m2", "capture_area_m2",
                                     "grasp_place_success"}
    with pytest.raises(StudyError, match="no variant"):
        studies.show("not-a-variant")
    (folder / f"{from_csv.variants[0]}.toml").unlink()
    with pytest.raises(StudyError, match="no robot file"):
        studies.show(from_csv.variants[0])
    assert studies.shown is None
