"""The header (one STOP, control, phase, link) and the tabs by task, without a browser."""

from __future__ import annotations

from typing import Any

import pytest

from console.panels.common.header import FIELDS
from console.panels.common.base import Panel
from console.panels.common.jog import JogPanel
from console.panels.common.readout import ReadoutPanel
from console.panels.common.session import SessionPanel
from console.panels.common.tabs import TAB_ORDER
from core.robots import load
from tests.fakes import FakeClient, console_app

SOFT = load("soft-arm")


class _HardwareLike(Panel):
    title = "Fake hardware"
    tab = "Hardware"

    def build(self) -> None:
        self.gui.add_markdown("hardware")


class _ExperimentLike(Panel):
    title = "Fake experiment"
    tab = "Experiments"

    def build(self) -> None:
        self.gui.add_markdown("experiment")


def _inputs(server: Any) -> dict[str, Any]:
    return dict(server.gui._gui_input_handle_from_uuid)


def _tab_labels(app: Any) -> tuple[str, ...]:
    """What the browser receives: the tab group's labels as sent in its props."""
    return tuple(app.tabs._group._tab_labels)


def test_tabs_keep_the_task_order_whatever_order_panels_are_added_in(server: Any) -> None:
    app = console_app(SOFT, server, panels=(SessionPanel, _ExperimentLike, JogPanel,
                                            _HardwareLike))
    assert _tab_labels(app) == ("Operate", "Hardware", "Experiments", "Session")
    assert app.tabs.names == _tab_labels(app)


def test_a_robot_without_experiments_gets_no_empty_tab(server: Any) -> None:
    app = console_app(SOFT, server, panels=(SessionPanel, JogPanel, ReadoutPanel))
    assert _tab_labels(app) == ("Operate", "Session")


def test_each_panel_folder_is_built_inside_its_tab(server: Any) -> None:
    app = console_app(SOFT, server, panels=(JogPanel, SessionPanel, _HardwareLike))
    by_label = {h._label: h._id for h in app.tabs._group._tab_handles}
    for panel in app.panels:
        assert panel.folder._impl.parent_container_id == by_label[panel.tab], panel.title


def test_an_unknown_tab_is_refused_by_name(server: Any) -> None:
    app = console_app(SOFT, server, panels=())
    with pytest.raises(ValueError, match="Operate, Hardware, Experiments, Session"):
        app.tabs.tab("Misc")
    assert set(TAB_ORDER) == {"Operate", "Hardware", "Experiments", "Session"}


def test_header_shows_fields_in_order_escapes_text_and_hides_empty_ones(server: Any) -> None:
    app = console_app(SOFT, server, panels=())
    app.header.show("link", "emulator · <b>active</b>", tone="ok")
    app.header.show("phase", "moving · waypoint 2/5", tone="busy")
    page = app.header.status.content
    assert page.index('data-testid="header-phase"') < page.index('data-testid="header-link"')
    assert "&lt;b&gt;active&lt;/b&gt;" in page and "<b>active</b>" not in page
    assert "#1c7ed6" in page  # busy
    app.header.show("phase", "")
    assert 'data-testid="header-phase"' not in app.header.status.content
    with pytest.raises(ValueError, match="unknown header field"):
        app.header.show("weather", "sunny")
    assert FIELDS == ("control", "phase", "link")


def test_the_session_panel_tells_the_header_who_holds_control(server: Any) -> None:
    app = console_app(SOFT, server, panels=(SessionPanel,))
    assert "nobody" in app.header.text("control")
    assert 'data-testid="holder"' in app.header.status.content


def test_there_is_one_stop_and_it_stops_for_a_viewer(server: Any) -> None:
    app = console_app(SOFT, server, panels=(JogPanel, ReadoutPanel, SessionPanel))
    labels = [h._impl.props.label for h in _inputs(app.server).values()
              if "STOP" in str(getattr(h._impl.props, "label", ""))]
    assert labels == ["STOP  (Esc)"]  # the Session panel's own STOP is gone

    class _Event:
        client = FakeClient(7)
        client_id = 7

    app.header._on_stop(_Event())
    assert app.stops == 1 and app.last_stop.reason == "STOP pressed by client 7"
    assert app.last_stop.who == "client 7"
    assert app.guard.viewer_allowed(app.header.stop_btn)
