"""Operate fits the task (issue 31 item 3), read from the GUI tree viser sends, without a browser:
what a demo presses sits at the top of Operate, open; editing and diagnostics are folded below.

The expected layouts are the issue's: soft arm Plan, then Arm and Execute with the selected
object named, the legend and cameras one click away, objects/obstacles/planner settings and the
loop's statistics and plots folded; extensible arm the tip target, then the paths."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import viser

from console.panel_sets import DEFAULT_PANELS
from console.panels.common.view import ViewPanel
from console.panels.extensible.panel_set import EXTENSIBLE_PANELS
from console.panels.soft_arm.control import ControlPanel
from console.panels.soft_arm.panel_set import grasp_panels
from console.panels.soft_arm.planner import PlannerPanel
from core.robots import load
from tests.fakes import FakeRunner, console_app
from tests.ws_client import wait_for

SOFT = load("soft-arm")
EXT = load("extensible")


class _IdleControl:
    """The soft arm's control process before its first view: what the Control panel reads."""

    alive = True
    failure = None
    view = None

    def view_age(self) -> float:
        return float("inf")

    def close(self) -> None:
        pass


def _cid(container: Any) -> str:
    """The id its children name as their parent (a tab's ``_id``, a folder's uuid)."""
    return container._impl.uuid if hasattr(container, "_impl") else container._id


def _children(app: Any, container: Any) -> list[Any]:
    """The handles viser shows in ``container``, in the order the browser draws them."""
    handle = app.server.gui._container_handle_from_uuid[_cid(container)]
    return sorted(handle._children.values(), key=lambda h: h.order)


def _operate(app: Any) -> list[Any]:
    return _children(app, app.tabs.tab("Operate"))


def _folders(app: Any) -> list[tuple[str, bool]]:
    """Operate's top-level folders: (label, open when the page loads)."""
    return [(h.label, h.expand_by_default) for h in _operate(app)
            if hasattr(h, "expand_by_default")]


def _parent(handle: Any) -> str:
    return handle._impl.parent_container_id


@pytest.fixture
def soft(server: Any) -> Any:
    app = console_app(SOFT, server, soft_control=_IdleControl(),
                      panels=(*DEFAULT_PANELS, *grasp_panels(), ControlPanel, ViewPanel))
    control = app.panel(ControlPanel)
    control._pump_stop.set()
    control._pump.join(2.0)
    return app


def test_soft_arm_operate_starts_with_plan_then_arm_and_execute_and_folds_the_rest(
        soft: Any) -> None:
    assert _folders(soft) == [("Grasp planner", True), ("Control", True), ("View", False),
                              ("Objects", True), ("Waypoints", False), ("Jog", False),
                              ("Readout", False)]
    planner, control = soft.panel(PlannerPanel), soft.panel(ControlPanel)
    # what a table click places comes first (to place the bin before "Clear table into bin"
    # it had to be found in the Objects folder, below the fold at 1600 x 1000)
    from console.panels.soft_arm.objects import ObjectsPanel
    assert _operate(soft)[0] is soft.panel(ObjectsPanel).click_place
    assert _operate(soft)[1] is planner.folder
    # Plan grasp is the first thing in the Grasp planner, then the object it plans for
    first = _children(soft, planner.folder)
    assert first[0] is planner.plan_button and first[1] is planner.plan_for
    # Arm, Disarm, Execute, Click to grasp and Clear table are in the Control folder itself
    shown = _children(soft, control.folder)
    for handle in (control.arm_btn, control.disarm_btn, control.execute.execute_btn,
                   control.execute.click_mode, control.row.button, control.execute.target_md):
        assert handle in shown, handle.label if hasattr(handle, "label") else handle
    assert shown.index(control.arm_btn) < shown.index(control.execute.execute_btn)


def test_the_running_tasks_progress_is_right_under_the_state_above_arm_and_execute(
        soft: Any) -> None:
    """Seen in the demo's screenshots at 1600 x 1000: the progress bar and "Running: … waypoint
    i of n · ≈ 42 s left" sat below Execute, the row's line and Clear table, off screen while
    the arm ran. They come right after the state line (and its fault line), before Arm."""
    control = soft.panel(ControlPanel)
    shown = _children(soft, control.folder)
    bar, line = shown.index(control.progress.bar), shown.index(control.progress.line)
    assert shown.index(control.state_md) < shown.index(control.fault_md) < bar < line
    assert line < shown.index(control.arm_btn) < shown.index(control.execute.execute_btn)


def test_soft_arm_diagnostics_and_editing_are_folded(soft: Any) -> None:
    from console.panels.soft_arm.objects import ObjectsPanel

    control, planner = soft.panel(ControlPanel), soft.panel(PlannerPanel)
    objects = soft.panel(ObjectsPanel)
    diag = control.diagnostics
    assert diag.label == "Loop diagnostics" and not diag.expand_by_default
    assert _parent(diag) == _cid(control.folder)
    for handle in (control.link_md, control.kappa_md, control.loop_md):
        assert _parent(handle) == _cid(diag)
    plots = [h for h in _children(soft, diag) if type(h).__name__ == "GuiUplotHandle"]
    assert len(plots) == 2  # tracking error and loop timing: both folded
    settings = planner.settings
    assert settings.label == "Planner settings" and not settings.expand_by_default
    for handle in (planner.delta_d, planner.weights, planner.clearance, planner.live,
                   planner.reach):
        assert _parent(handle) == _cid(settings)
    # Objects: which object is selected stays in view (what a click places is above Plan)
    assert _parent(objects.click_place) == _cid(soft.tabs.tab("Operate"))
    assert _parent(objects.selected) == _cid(objects.folder)
    for fold in (objects.editing, objects.obstacles.folder):
        assert _parent(fold) == _cid(objects.folder) and not fold.expand_by_default
    for handle in (objects.x, objects.y, objects.r, objects.add_button, objects.remove_button,
                   objects.save_button, objects.load_button):
        assert _parent(handle) == _cid(objects.editing)


def test_the_plan_line_names_the_selected_object_in_mm(soft: Any) -> None:
    planner = soft.panel(PlannerPanel)
    session = soft.soft_arm_grasp()
    session.place(-0.2, 0.25, r=0.02)
    name = session.view().selected
    assert name
    # (the session tells its listeners on its worker: wait for the line, then read it)
    wait_for(lambda: f'data-object="{name}"' in planner.plan_for.content, what="the new object")
    text = planner.plan_for.content
    assert f"<b>{name}</b>" in text and "(-200, 250) mm" in text and "⌀ 40 mm" in text
    for o in list(session.view().objects):
        session.remove(o.name)
    wait_for(lambda: 'data-object=""' in planner.plan_for.content, what="no object")
    assert "No object selected" in planner.plan_for.content


def test_the_legend_and_cameras_are_one_click_away_below_the_task(soft: Any) -> None:
    view = soft.panel(ViewPanel)
    names = [label for label, _ in _folders(soft)]
    assert names.index("View") == names.index("Control") + 1  # no open panel between
    assert _parent(view.legend) == _cid(view.folder)
    assert all(_parent(b) == _cid(view.folder) for b in view.cameras.values())


def test_extensible_operate_starts_with_the_target_then_paths(server: Any) -> None:
    app = console_app(EXT, server, extensible_runner=FakeRunner(),
                      panels=(*DEFAULT_PANELS, *EXTENSIBLE_PANELS, ViewPanel))
    assert _folders(app) == [("Tip target", True), ("Paths", True), ("View", False),
                             ("Obstacles (boxes)", False), ("Jog", False), ("Readout", False)]


# -- narrow screens -------------------------------------------------------------------------

VISER_CLIENT = Path(viser.__file__).parent / "client" / "src"


def test_the_control_panel_is_docked_beside_the_3d_view(server: Any, monkeypatch: Any) -> None:
    """Docked (not floating over it), the panel never covers the arm framed in the 3D view."""
    from viser._gui_handles import MainPanelHandle

    docked: list[str] = []
    monkeypatch.setattr(MainPanelHandle, "dock_right", lambda self: docked.append("right"))
    monkeypatch.setattr(MainPanelHandle, "dock_left", lambda self: docked.append("left"))
    console_app(SOFT, server, panels=())
    assert docked == ["right"]


def test_a_theme_with_an_unknown_dock_is_refused(tmp_path: Path) -> None:
    from console.scene.theme import THEME_FILE, load_theme

    text = THEME_FILE.read_text(encoding="utf-8")
    assert 'control_dock = "right"' in text
    bad = tmp_path / "theme.toml"
    bad.write_text(text.replace('control_dock = "right"', 'control_dock = "top"'))
    with pytest.raises(ValueError, match=r"\[gui\] control_dock"):
        load_theme(bad)
    bad.write_text(text.replace('control_dock = "right"', 'control_dock = "float"'))
    assert load_theme(bad).control_dock == "float"


@pytest.mark.skipif(not (VISER_CLIENT / "ControlPanel" / "BottomPanel.tsx").exists(),
                    reason="viser's client source is not installed")
def test_the_phone_style_targets_the_sheet_viser_draws_on_phones() -> None:
    """Read against viser's own client source: phones (Mantine's xs breakpoint, 36 em by
    default) get a bottom sheet 20 em wide, at most 60 % high, and the 3D view's box (flex-grow
    1, height 100 %) fills the window; the style matches exactly those inline styles, on phones
    only, and makes the sheet the window's width and at most 50 % high, the view the other 50 %
    above it."""
    import re

    from console.web.phone_sheet import phone_sheet_css

    sheet = (VISER_CLIENT / "ControlPanel" / "BottomPanel.tsx").read_text(encoding="utf-8")
    app = (VISER_CLIENT / "App.tsx").read_text(encoding="utf-8")
    assert "(max-width: ${mantineTheme.breakpoints.xs})" in app
    assert 'maxHeight: "60%"' in sheet and sheet.count('width: "20em"') == 2
    css = phone_sheet_css()
    assert css.startswith("<style>@media (max-width: 36em) {") and css.endswith("}</style>")
    assert "backgroundColor: darkMode" in app and "flexGrow: 1,\n            height: \"100%\"" in app
    assert '[style*="max-height: 60%"]' in css and '[style^="width: 20em"]' in css
    assert re.search(r"\{width:100%!important;max-height:50%!important\}", css)
    assert re.search(r'div\[style\*="flex-grow: 1"\]\[style\*="height: 100%"\]:has\(canvas\)'
                     r"\{flex:0 0 auto!important;width:100%!important;height:50%!important\}", css)
    with pytest.raises(ValueError, match="height"):
        phone_sheet_css(max_height_pct=90)


def test_the_console_carries_the_phone_style(server: Any) -> None:
    from console.web.phone_sheet import phone_sheet_css

    console_app(SOFT, server, panels=())
    root = server.gui._container_handle_from_uuid["root"]
    styles = [h for h in root._children.values()
              if getattr(h, "content", None) == phone_sheet_css()]
    assert len(styles) == 1
