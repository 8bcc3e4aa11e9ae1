"""Browser-test helpers: the console's panels live in tabs (``console.tabs``), and a widget is in
the page only while its tab is open; notifications can cover widgets."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

ARTIFACTS = Path(__file__).resolve().parents[2] / "artifacts"


def open_tab(page: Any, name: str, timeout_ms: float = 60_000) -> None:
    """Click the tab ``name`` (Operate, Hardware, Experiments, Session) and wait until it shows."""
    tab = page.get_by_role("tab", name=name, exact=True)
    try:
        tab.wait_for(timeout=timeout_ms)
    except Exception:
        page.screenshot(path=str(ARTIFACTS / f"open_tab_{name.lower()}_failure.png"))
        raise
    if tab.get_attribute("aria-selected") != "true":
        tab.click()
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
