"""The two-browser lab rig: an in-process lab console and helpers that drive its pages
(shared by test_browser_lab.py and test_browser_lab_export.py)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Callable, Iterator

import pytest

from browser_tabs import open_folder, open_tab
from core.robots import load
from tests import ws_client

SOFT = load("soft-arm")


class Lab:
    """The in-process console plus helpers to drive pages."""

    def __init__(self, server: Any, app: Any, token: str, browser: Any) -> None:
        self.server, self.app, self.token, self.browser = server, app, token, browser
        self.url = f"http://127.0.0.1:{server.get_port()}/"
        self.contexts: list[Any] = []

    @property
    def stops(self) -> list[tuple[float, str]]:
        """Every stop of the console so far: (time.monotonic(), reason), from its core."""
        return [(r.at, r.reason) for r in self.app.core.stop_log]

    def page(self) -> Any:
        """A new browser (its own context, 1280x900) on the console, the Operate tab open."""
        return self.pages(1)[0]

    def pages(self, n: int) -> list[Any]:
        """``n`` new browsers on the console, each as :meth:`page`, loaded side by side: a load
        is seconds of software rendering, which two renderer processes share out over both
        cores."""
        before = len(self.server.get_clients())
        pages = []
        for _ in range(n):
            context = self.browser.new_context(viewport={"width": 1280, "height": 900})
            self.contexts.append(context)
            page = context.new_page()
            page.goto(self.url, wait_until="commit")  # the next starts loading meanwhile
            pages.append(page)
        for page in pages:
            open_tab(page, "Session")  # the per-browser role line and Take control live there
            page.locator('[data-testid="role"]').wait_for(timeout=10_000)
            open_tab(page, "Operate")
        wait_for(lambda: len(self.server.get_clients()) >= before + n)
        for page in pages:
            notice = page.locator(".mantine-Notification-root", has_text="Software WebGL")
            if notice.count():
                notice.locator("button").first.click()
        return pages

    def take_control(self, page: Any, name: str) -> None:
        """Take control in the Session tab, then open the Operate tab again."""
        open_tab(page, "Session")
        field(page, "Your name").fill(name)
        field(page, "Operator token").fill(self.token)
        page.get_by_role("button", name="Take control").click()
        wait_for(lambda: self.app.access.holder is not None
                 and self.app.access.holder.name == name)
        wait_for(lambda: page.locator('[data-testid="role"]').get_attribute("data-role")
                 == "operator")
        open_tab(page, "Operate")


def wait_for(predicate: Callable[[], Any], timeout: float = 5.0) -> Any:
    """tests/ws_client.wait_for with the lab tests' default of 5 s."""
    return ws_client.wait_for(predicate, timeout)


def field(page: Any, label: str) -> Any:
    """The input next to a viser text field's label."""
    return page.locator(f'xpath=//label[normalize-space()="{label}"]/ancestor::div'
                        '[contains(@class,"mantine-Flex-root")][1]//input')


def stop_button(page: Any) -> Any:
    """The header's STOP (above every tab)."""
    return page.get_by_role("button", name="STOP (Esc)").first


def notifications(page: Any) -> list[str]:
    # One snapshot: reading them one by one waits 30 s for one that closed in between.
    return page.locator(".mantine-Notification-root").all_inner_texts()


def session_button(page: Any, name: str) -> Any:
    """The Session tab's button labelled ``name`` (the tab is opened first)."""
    open_tab(page, "Session")
    return page.get_by_role("button", name=name)


def jog_button(page: Any, label: str, sign: str) -> Any:
    """The hold-to-jog button ``sign`` ("−" or "+") beside the Jog slider labelled ``label``
    (opens the Operate tab, where the Jog panel is, and unfolds the panel)."""
    open_tab(page, "Operate")
    open_folder(page, "Jog", page.locator("label", has_text=label))  # folded by default
    uid = page.locator("label", has_text=label).first.get_attribute("for")
    assert uid, f"no slider labelled {label!r}"
    # The slider's box, then the two button boxes after it in the same row of the folder.
    row = page.locator(f'xpath=//*[@id="{uid}"]/ancestor::div[following-sibling::div[1]/button][1]')
    button = row.locator("xpath=following-sibling::div[position() <= 2]/button").filter(
        has_text=sign)
    assert button.count() == 1, f"no {sign!r} beside {label!r}"
    return button


def press(page: Any, name: str | Any) -> Any:
    """Mouse down on the button labelled ``name`` (or the locator ``name``); returns the mouse
    to release."""
    if isinstance(name, str):
        open_tab(page, "Operate")
    button = page.get_by_role("button", name=name, exact=True) if isinstance(name, str) else name
    button.scroll_into_view_if_needed()
    box = button.bounding_box()
    assert box is not None
    page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    page.mouse.down()
    return page.mouse


def lab_app(tmp_path: Path, **services: Any) -> tuple[Any, Any, str]:
    """A viser server on a free port and a soft-arm ConsoleApp in lab mode with a fresh operator
    token and the given ``services`` (``fakes.console_app``; no panels yet); returns
    (server, app, token)."""
    import secrets

    import viser

    from console.core.access import AccessControl
    from fakes import console_app

    token = secrets.token_urlsafe(9)
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    app = console_app(SOFT, server, panels=(), access=AccessControl(token),
                      data_dir=tmp_path / "runs", status="lab test", **services)
    return server, app, token


@pytest.fixture
def lab(browser, tmp_path: Path) -> Iterator[Lab]:
    """A lab console as ``serve.py --lab --demo`` builds it (token, viewers first, demo motion),
    with the panels these tests use -- Jog, Readout, Control (the real Execute and the control
    process), Session -- rather than all of them: the full console takes twice as long to load
    in software-rendered Chromium, and the other panels play no part here."""
    from console.panel_sets import DEFAULT_PANELS
    from console.panels.soft_arm.control import ControlPanel
    from console.panels.common.session import SessionPanel

    server, app, token = lab_app(tmp_path, soft_control="process", demo=True)
    for panel_cls in (*DEFAULT_PANELS, ControlPanel, SessionPanel):
        app.add_panel(panel_cls)
    app.start()
    lab = Lab(server, app, token, browser)
    try:
        yield lab
    finally:
        for context in lab.contexts:
            context.close()
        app.stop_motion("test over")
        app.stop()
        app.services.close()
        app.services.soft_control.close()
        server.stop()
