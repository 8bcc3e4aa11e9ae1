"""Shared test fixtures: headless Chromium (Playwright) and a live ``serve.py`` subprocess.

Browser tests take ``browser`` (session-wide Chromium from /usr/bin/chromium; skipped when it is
missing, except under CI=true where that fails) and ``console_server`` (a factory that starts
``serve.py --robot NAME`` on a free 127.0.0.1 port, waits until it serves, returns its URL and
kills it at teardown). ``module_console_server`` and ``module_page`` are the same for the tests
of one module, to share one loaded console. Screenshots go to ``artifacts/`` (gitignored) via
``artifacts_dir``.
``serve_module`` is ``serve.py`` imported as a module (its ``build`` makes an in-process console).
``viser_patched`` (autouse, session) installs ``console.web``'s patches of viser, as serve.py does.
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
from typing import Any, Callable, Iterator

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
SERVER_START_TIMEOUT = 60.0  # (about 2 s on a quiet machine)
# The 3D view's drawing-buffer scale in browser tests (viser's ``?fixedDpr=``): Chromium draws
# WebGL in software here, and its cost grows with the pixels drawn; half the resolution draws a
# quarter of them. Page layout (CSS pixels), clicks and DOM screenshots are unchanged; only the
# 3D picture is coarser. BROWSER_TEST_DPR=1 draws at full resolution.
RENDER_DPR = os.environ.get("BROWSER_TEST_DPR", "0.5")
# Run in every page before its own scripts: the console's pages (http) draw at RENDER_DPR;
# exported files opened from disk are left alone.
_DPR_SCRIPT = """(() => {
    if (location.protocol !== "http:") return;
    const q = new URLSearchParams(location.search);
    if (q.has("fixedDpr")) return;
    q.set("fixedDpr", "%s");
    history.replaceState(history.state, "", location.pathname + "?" + q + location.hash);
})();"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="session", autouse=True)
def viser_patched() -> None:
    """``console.web.install()`` once for the session, as ``serve.py`` does before its server:
    ``ConsoleApp`` refuses to build without it (tests that look at upstream viser uninstall and
    reinstall around themselves, ``tests/console/test_web_patches.py``)."""
    from console import web

    web.install()


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
        if RENDER_DPR != "1":
            new_context = chromium.new_context

            def scaled_context(*args: object, **kwargs: object) -> object:
                context = new_context(*args, **kwargs)
                context.add_init_script(_DPR_SCRIPT % float(RENDER_DPR))
                return context

            chromium.new_context = scaled_context  # type: ignore[method-assign]
        try:
            yield chromium
        finally:
            chromium.close()


def _new_page(browser: object) -> tuple[object, object]:
    context = browser.new_context(viewport={"width": 1280, "height": 800})  # type: ignore[attr-defined]
    return context, context.new_page()


@pytest.fixture
def page(browser: object) -> Iterator[object]:
    """A fresh 1280x800 page; closed after the test."""
    context, pg = _new_page(browser)
    try:
        yield pg
    finally:
        context.close()


@pytest.fixture(scope="module")
def module_page(browser: object) -> Iterator[object]:
    """A 1280x800 page shared by the tests of one module (each console load costs seconds of
    software rendering); closed after the module's last test."""
    context, pg = _new_page(browser)
    try:
        yield pg
    finally:
        context.close()


class ConsoleServers:
    """Starts ``serve.py --robot NAME`` subprocesses on free ports; :meth:`close` kills them."""

    def __init__(self) -> None:
        self.procs: list[subprocess.Popen[bytes]] = []
        self.logs: dict[str, Path] = {}

    def log(self, url: str) -> str:
        """What the server at ``url`` printed so far (stdout and stderr)."""
        return self.logs[url].read_text()

    def start(self, robot: str, *extra: str, hardware: str | None = "mock") -> str:
        """Start serve.py (``--hardware mock`` unless ``hardware`` says otherwise; None: its
        default), wait until it serves, return its base URL; :meth:`log` is what it printed."""
        port = _free_port()
        log = REPO / "artifacts" / f"serve-{Path(robot).stem}-{port}.log"  # one per server
        log.parent.mkdir(exist_ok=True)
        out = log.open("wb")
        device = ["--hardware", hardware] if hardware is not None else []
        proc = subprocess.Popen(
            [sys.executable, str(REPO / "serve.py"), "--robot", robot, "--host", "127.0.0.1",
             "--port", str(port), *device, *extra],
            cwd=REPO, stdout=out, stderr=subprocess.STDOUT,
            env={**os.environ, "PYTHONUNBUFFERED": "1"})  # the log is current while it runs
        out.close()
        self.procs.append(proc)
        url = f"http://127.0.0.1:{port}/"
        self.logs[url] = log
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

    __call__ = start

    def close(self) -> None:
        for proc in self.procs:
            proc.terminate()
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=5)


@pytest.fixture
def console_server() -> Iterator[ConsoleServers]:
    """Factory: ``console_server("soft-arm")`` starts serve.py and returns its base URL
    (:meth:`ConsoleServers.start`; ``console_server.log(url)``: what it printed)."""
    servers = ConsoleServers()
    yield servers
    servers.close()


@pytest.fixture(scope="module")
def module_console_server() -> Iterator[ConsoleServers]:
    """``console_server`` for one module: the servers live until its last test ends."""
    servers = ConsoleServers()
    yield servers
    servers.close()


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


@pytest.fixture
def served_console(serve_module: Any, tmp_path: Path) -> Iterator[Callable[..., Any]]:
    """``served_console(robot, hardware="mock", *more_args, start=False)``: the console serve.py
    builds for ``robot`` (``--no-token``, a free port, no CPU pinning, data under the test's
    tmp_path), in this process; shut down after the test as serve.py does. Not started unless
    asked: a started console's lease would take control from a headless FakeClient."""
    built: list[tuple[Any, Any]] = []

    def serve(robot: str | Path, hardware: str = "mock", *more_args: str,
              start: bool = False) -> Any:
        from core.robots import load
        args = serve_module.parse_args(["--robot", str(robot), "--no-token", "--port", "0",
                                        "--hardware", hardware, "--rt-cpu", "none",
                                        "--data-dir", str(tmp_path / "runs"), *more_args])
        server, app, token = serve_module.build(args, load(args.robot), "test")
        built.append((server, app))
        assert token is None
        return app.start() if start else app

    yield serve
    for server, app in built:
        for _, step in serve_module._shutdown_steps(app, server):
            step()


def pytest_configure(config: pytest.Config) -> None:
    """Register the ``browser`` marker (tests that drive Chromium against serve.py), the
    ``timing`` marker (tests whose assertions hold wall-clock limits: the timing part) and the
    ``alone`` marker (browser tests whose assertions hold tight wall-clock limits or need the
    page's full frame rate)."""
    config.addinivalue_line("markers", "browser: drives headless Chromium against serve.py")
    config.addinivalue_line(
        "markers", "timing: assertions hold wall-clock limits: run one at a time with nothing "
        "beside them (SUITE_PART=timing)")
    config.addinivalue_line(
        "markers", "alone: a browser test with tight wall-clock limits (a 300 ms hold expiry, "
        "a 1 s answer, the lease) or that samples a readout at the page's frame rate, or a "
        "test that loads every core on purpose (CPU hogs): SUITE_PART=alone runs it with "
        "nothing else beside it")
    config.addinivalue_line(
        "markers", "slow(seconds): runs long on the wall clock (a simulated arm in real time, "
        "about `seconds` on two busy cores): the parallel part starts it first, the longest "
        "first, so the run does not end waiting for it alone")


def xdist_group_of(item: pytest.Item) -> str | None:
    """The group ``item`` runs in: "browser" for every browser test (tests/browser/; each loads
    Chromium's software renderer, and several hold timings: a 300 ms hold, the lease), "timing"
    for a test marked ``timing`` or ``alone`` (one at a time: its assertions hold wall-clock
    limits, or it loads every core on purpose), None for the others, which spread over both
    pytest-xdist workers."""
    if item.nodeid.split("::", 1)[0].startswith("tests/browser/"):
        return "browser"
    one_at_a_time = any(item.get_closest_marker(m) is not None for m in ("timing", "alone"))
    return "timing" if one_at_a_time else None


SUITE_PARTS = ("parallel", "browser", "serial", "timing", "alone")


def suite_part_of(item: pytest.Item) -> str:
    """Which part of scripts/test runs ``item``: "parallel" (no group, :func:`xdist_group_of`),
    "browser" (a browser test without the ``alone`` marker: two at a time, a file per worker)
    or "serial" (the tests marked ``timing`` and the ``alone`` tests: one at a time)."""
    group = xdist_group_of(item)
    if group is None:
        return "parallel"
    if group == "browser" and item.get_closest_marker("alone") is None:
        return "browser"
    return "serial"


def in_suite_part(item: pytest.Item, part: str) -> bool:
    """Whether ``SUITE_PART=part`` runs ``item``: a part of :func:`suite_part_of`, or one half
    of "serial": "alone" (marked ``alone``) or "timing" (the rest)."""
    own = suite_part_of(item)
    if part in ("timing", "alone"):
        return own == "serial" and (item.get_closest_marker("alone") is not None) == (
            part == "alone")
    return own == part


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """``SUITE_PART=parallel|browser|serial|timing|alone`` keeps only that part's tests
    (:func:`in_suite_part`). scripts/test runs them one after another: the parallel part on
    two workers, the browser tests two at a time (each waits much of its time for the
    simulated arm or a page's round trips), then the timing tests and the ``alone`` tests one
    at a time, so no tight wall-clock assertion shares the cores."""
    part = os.environ.get("SUITE_PART", "")
    if part not in SUITE_PARTS:
        return
    keep, drop = [], []
    for item in items:
        (keep if in_suite_part(item, part) else drop).append(item)
    if drop:
        config.hook.pytest_deselected(items=drop)
        items[:] = keep
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "0") or 0)
    if part == "parallel" and workers > 1:
        items[:] = slow_first(items, workers)


def slow_first(items: list[Any], workers: int) -> list[Any]:
    """``items`` reordered so that pytest-xdist's load scheduling starts the tests marked
    ``slow`` first, the longest first (the marker's seconds), one per worker: its first
    batches are consecutive chunks of ``max(len(items) // workers // 4, 2)`` items, one per
    worker, and the rest goes out in order as workers run low. So the first ``workers`` slow tests open those chunks and the
    others lead what is sent next; the other tests keep their order. (Every worker collects
    and reorders the same list: xdist requires identical collections.)"""
    slow = sorted((i for i in items if i.get_closest_marker("slow") is not None),
                  key=lambda i: -float((i.get_closest_marker("slow").args or (0,))[0]))
    if not slow:
        return items
    rest = [i for i in items if i.get_closest_marker("slow") is None]
    chunk = max(len(items) // workers // 4, 2)
    ordered: list[Any] = []
    for k in range(workers):
        ordered += slow[k:k + 1] + rest[:chunk - (k < len(slow))]
        rest = rest[chunk - (k < len(slow)):]
    return ordered + slow[workers:] + rest


# Per-test wall and CPU seconds when PYTEST_CPU_TIMES=FILE (tests/cpu_times.py).
pytest_plugins = ["cpu_times"]
