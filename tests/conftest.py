"""Shared test fixtures: headless Chromium (Playwright) and a live ``serve.py`` subprocess.

Browser tests take ``browser`` (session-wide Chromium from /usr/bin/chromium; skipped when it is
missing, except under CI=true where that fails) and ``console_server`` (a factory that starts
``serve.py --robot NAME`` on a free 127.0.0.1 port, waits until it serves, returns its URL and
kills it at teardown). Screenshots go to ``artifacts/`` (gitignored) via ``artifacts_dir``.
``serve_module`` is ``serve.py`` imported as a module (its ``build`` makes an in-process console).
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path
from typing import Callable, Iterator

import pytest

REPO = Path(__file__).resolve().parent.parent
CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]
SERVER_START_TIMEOUT = 30.0


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="session")
def artifacts_dir() -> Path:
    """``artifacts/`` at the repository root, created on demand."""
    path = REPO / "artifacts"
    path.mkdir(exist_ok=True)
    return path


@pytest.fixture(scope="session")
def browser() -> Iterator[object]:
    """Headless Chromium launched by Playwright (sync API)."""
    if not CHROMIUM.exists():
        message = f"{CHROMIUM} is missing (install Debian's chromium)"
        if os.environ.get("CI") == "true":
            pytest.fail(message)
        pytest.skip(message)
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        chromium = pw.chromium.launch(executable_path=str(CHROMIUM), headless=True,
                                      args=CHROMIUM_ARGS)
        try:
            yield chromium
        finally:
            chromium.close()


@pytest.fixture
def page(browser: object) -> Iterator[object]:
    """A fresh 1280x800 page; closed after the test."""
    context = browser.new_context(viewport={"width": 1280, "height": 800})  # type: ignore[attr-defined]
    pg = context.new_page()
    try:
        yield pg
    finally:
        context.close()


@pytest.fixture
def console_server() -> Iterator[Callable[..., str]]:
    """Factory: ``console_server("soft-arm")`` starts serve.py and returns its base URL."""
    procs: list[subprocess.Popen[bytes]] = []

    def start(robot: str, *extra: str) -> str:
        port = _free_port()
        log = REPO / "artifacts" / f"serve-{Path(robot).stem}-{port}.log"  # one per server
        log.parent.mkdir(exist_ok=True)
        out = log.open("wb")
        proc = subprocess.Popen(
            [sys.executable, str(REPO / "serve.py"), "--robot", robot, "--host", "127.0.0.1",
             "--port", str(port), "--hardware", "mock", *extra],
            cwd=REPO, stdout=out, stderr=subprocess.STDOUT)
        out.close()
        procs.append(proc)
        url = f"http://127.0.0.1:{port}/"
        deadline = time.monotonic() + SERVER_START_TIMEOUT
        while time.monotonic() < deadline:
            if proc.poll() is not None:
                pytest.fail(f"serve.py exited with {proc.returncode}:\n{log.read_text()}")
            try:
                with urllib.request.urlopen(url, timeout=1.0) as resp:
                    if resp.status == 200:
                        return url
            except (urllib.error.URLError, ConnectionError, TimeoutError):
                time.sleep(0.1)
        pytest.fail(f"serve.py did not serve {url} within {SERVER_START_TIMEOUT:.0f} s:\n"
                    f"{log.read_text()}")

    yield start
    for proc in procs:
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5)


@pytest.fixture
def server() -> Iterator[object]:
    """A viser server on a free 127.0.0.1 port, stopped after the test."""
    import viser

    srv = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        yield srv
    finally:
        srv.stop()


@pytest.fixture(scope="session")
def serve_module() -> object:
    """``serve.py`` imported as a module (it is a script at the repository root)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("serve", REPO / "serve.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def pytest_configure(config: pytest.Config) -> None:
    """Register the ``browser`` marker (tests that drive Chromium against serve.py)."""
    config.addinivalue_line("markers", "browser: drives headless Chromium against serve.py")
