"""Browser-test helpers: the console's panels live in tabs (``console.panels.common.tabs``), and a widget is in
the page only while its tab is open; notifications can cover widgets. :func:`wait_until` is
tests/ws_client.wait_for for pages."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Callable

from tests.ws_client import wait_for

ARTIFACTS = Path(__file__).resolve().parents[2] / "artifacts"


def wait_until(what: str, fn: Callable[[], Any], timeout: float = 10.0,
               show: Callable[[], str] | None = None) -> Any:
    """Poll ``fn`` (page reads) every 0.05 s until it returns a true value (returned); after
    ``timeout`` s fail naming ``what`` and, when given, ``show()`` (what the page says then).
    (Each read is a round trip to Chromium, which a loaded machine's software renderer
    answers slowly: not polled as often as ws_client's server-side reads.)"""
    try:
        return wait_for(fn, timeout, what, interval=0.05)
    except AssertionError as exc:
        if show is None:
            raise
        raise AssertionError(f"{exc}: {show()}") from None


def open_folder(page: Any, title: str, inside: Any, timeout_ms: float = 30_000) -> None:
    """Unfold the folder titled ``title`` (Operate folds editing and diagnostics) unless
    ``inside`` (a locator of something in it) already shows; wait until it does."""
    if not inside.first.is_visible():
        page.get_by_text(title, exact=True).first.click()
    inside.first.wait_for(state="visible", timeout=timeout_ms)


def open_tab(page: Any, name: str, timeout_ms: float = 60_000) -> None:
    """Click the tab ``name`` (Operate, Hardware, Experiments, Session) and wait until it shows
    (notifications piled over it are closed, and the click goes through what covers it)."""
    tab = page.get_by_role("tab", name=name, exact=True)
    try:
        tab.wait_for(timeout=timeout_ms)
    except Exception:
        page.screenshot(path=str(ARTIFACTS / f"open_tab_{name.lower()}_failure.png"))
        raise
    if tab.get_attribute("aria-selected") != "true":
        try:
            tab.click(timeout=min(timeout_ms, 10_000))
        except Exception:  # noqa: BLE001 - covered (notices pile up on a stalled tab): again
            close_notices(page)
            tab.click(force=True, timeout=timeout_ms)
    page.wait_for_function(
        "n => [...document.querySelectorAll('[role=tab]')].some("
        "t => t.textContent.trim() === n && t.getAttribute('aria-selected') === 'true')",
        arg=name, timeout=timeout_ms)


def close_notices(page: Any) -> None:
    """Close every notification shown (one that closes on its own meanwhile is skipped)."""
    from playwright.sync_api import Error as PlaywrightError
    for notice in page.locator(".mantine-Notification-root").all():
        try:
            notice.locator("button").first.click(timeout=1_000)
        except PlaywrightError:
            continue


def close_notices_until_none(page: Any) -> None:
    """Close every notification (they can cover the canvas) and wait until none is left: the
    browser's own "Software WebGL rendering detected" appears at mount and stays until closed,
    and a close button clicked on a busy page may take seconds to act."""
    deadline = time.monotonic() + 20
    notices = page.locator(".mantine-Notification-root")
    while notices.count() and time.monotonic() < deadline:
        try:
            notices.first.locator("button").first.click(timeout=5_000)
            notices.first.wait_for(state="detached", timeout=5_000)
        except Exception:  # noqa: BLE001, S110 - closed by itself meanwhile, or slow to detach
            pass
    assert notices.count() == 0, [n.inner_text() for n in notices.all()]


def open_console(page: Any, url: str, panel: str, ready: str | None = None, *,
                 role: str | None = None, no_notices: bool = False,
                 timeout_ms: float = 60_000) -> None:
    """Load the console at ``url`` and wait until it can be used from the Operate tab.

    Waits for the panel titled ``panel`` (and the element ``ready``, a CSS selector, when given)
    in the Operate tab. With ``role`` ("any" or "operator") the Session tab's per-browser role
    line must be there first (as ``role`` when "operator"): serve.py answers HTTP before its
    panels exist, and a browser that connected that early gets no per-browser Session widgets,
    so the page is reloaded once if the line is missing. Last, the notifications shown are
    closed (the browser's own "Software WebGL" notice stays until closed; they cover widgets
    and the 3D canvas), with ``no_notices`` until none is left (:func:`close_notices_until_none`).
    """
    page.goto(url)
    if role is not None:
        page.locator('[data-testid="holder"]').wait_for(timeout=timeout_ms)  # (in the header)
        open_tab(page, "Session", timeout_ms)
        line = page.locator('[data-testid="role"]')
        if line.count() == 0:
            page.reload()
            open_tab(page, "Session", timeout_ms)
        if role == "operator":
            line = page.locator('[data-testid="role"][data-role="operator"]')
        line.wait_for(timeout=timeout_ms)
    open_tab(page, "Operate", timeout_ms)
    page.get_by_text(panel, exact=True).first.wait_for(timeout=timeout_ms)
    if ready is not None:
        page.locator(ready).first.wait_for(timeout=timeout_ms)
    (close_notices_until_none if no_notices else close_notices)(page)


# viser's client sets its 3D canvas's cursor to "pointer" once the server's scene-click binding
# has arrived (HoverCursorManager; a click before that sends nothing to the server).
_SCENE_CLICKABLE = ("() => [...document.querySelectorAll('canvas')]"
                    ".some(c => c.style.cursor === 'pointer')")
_TOP_ELEMENT = """([x, y]) => {
    const e = document.elementFromPoint(x, y);
    return e === null ? "nothing" : e.tagName + (e.className ? "." + e.className : "");
}"""


def click_scene(page: Any, x: float, y: float, timeout_ms: float = 30_000) -> None:
    """Click the 3D view at page pixel (x, y) once a click there can reach the server: the
    scene-click binding has arrived and nothing (a notification, a panel) is drawn over the
    point (else fails naming what is)."""
    page.wait_for_function(_SCENE_CLICKABLE, timeout=timeout_ms)
    top = page.evaluate(_TOP_ELEMENT, [x, y])
    assert top.startswith("CANVAS"), f"{top} is over the 3D view at ({x:.0f}, {y:.0f})"
    page.mouse.click(x, y)
