"""``console.web.resting_redraw``: servers serve viser's own page with the resting-redraw script
first in its ``<head>`` and nothing else changed; upstream viser (the patch undone) serves its
page as built; a build the patch does not know is served as built, with a warning.

Fetched over HTTP with an independent client (``urllib``), compared byte for byte with viser's
``client/build/index.html`` and ``static/resting_redraw.js`` read here. What the script does in a
browser is tested on a simulated clock in ``tests/browser/test_resting_redraw_browser.py``.
"""

from __future__ import annotations

import gzip
import logging
import tempfile
import urllib.request
from pathlib import Path

import pytest
import viser
from viser.infra import _infra

from fakes import upstream_viser as upstream
from console.web import resting_redraw

BUILD = Path(viser.__file__).resolve().parent / "client" / "build" / "index.html"
SCRIPT = (Path(__file__).resolve().parents[2] / "static" / "resting_redraw.js").read_bytes()


def _page(server: viser.ViserServer, gzipped: bool = False) -> bytes:
    request = urllib.request.Request(f"http://127.0.0.1:{server.get_port()}/",
                                     headers={"Accept-Encoding": "gzip" if gzipped else ""})
    with urllib.request.urlopen(request, timeout=10) as resp:
        body = resp.read()
        return gzip.decompress(body) if resp.headers.get("Content-Encoding") == "gzip" else body


def _serve() -> viser.ViserServer:
    return viser.ViserServer(host="127.0.0.1", port=0, verbose=False)


def test_a_server_serves_visers_page_with_the_script_first_in_its_head_and_nothing_else() -> None:
    built = BUILD.read_bytes()
    server = _serve()
    try:
        page, zipped = _page(server), _page(server, gzipped=True)
    finally:
        server.stop()
    tag = b"<script>" + SCRIPT + b"</script>"
    assert page == zipped and page.count(tag) == 1
    head = page.index(b"<head>") + len(b"<head>")
    assert page[head:head + len(tag)] == tag  # before viser's bundle and anything else
    assert page.replace(tag, b"", 1) == built


def test_upstream_viser_serves_its_page_as_built() -> None:
    with upstream():
        assert not resting_redraw.installed()
        server = _serve()
        try:
            page = _page(server)
        finally:
            server.stop()
    assert page == BUILD.read_bytes() and SCRIPT not in page
    assert resting_redraw.installed()


def test_install_is_idempotent_and_uninstall_puts_visers_start_back() -> None:
    patched = _infra.WebsockServer.start
    original = patched.__wrapped__
    assert not resting_redraw.install() and _infra.WebsockServer.start is patched
    with upstream():
        assert _infra.WebsockServer.start is original
        assert not resting_redraw.uninstall()
    assert resting_redraw.installed() and _infra.WebsockServer.start.__wrapped__ is original


def test_a_server_with_its_own_root_is_left_alone(tmp_path: Path) -> None:
    (tmp_path / "index.html").write_bytes(b"<html><head></head><body>own</body></html>")
    server = _infra.WebsockServer("127.0.0.1", 0, http_server_root=tmp_path, verbose=False)
    assert server._http_server_root == tmp_path


@pytest.mark.parametrize("files, why", [
    ({"index.html": b"<html><head></head></html>", "extra.js": b""}, "not index.html alone"),
    ({"index.html": b"<html><body>no head</body></html>"}, "has no <head>"),
])
def test_a_build_the_patch_does_not_know_is_served_as_built_with_a_warning(
        tmp_path: Path, files: dict[str, bytes], why: str, caplog) -> None:
    for name, data in files.items():
        (tmp_path / name).write_bytes(data)
    with caplog.at_level(logging.WARNING, "console.web.resting_redraw"):
        assert resting_redraw.patched_root(tmp_path) is None
    assert any(why in r.getMessage() and "redrawing once a second" in r.getMessage()
               for r in caplog.records)


def test_the_patched_folder_is_named_by_its_page_and_rewritten_if_damaged(tmp_path: Path,
                                                                           monkeypatch) -> None:
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    build = tmp_path / "build"
    build.mkdir()
    (build / "index.html").write_bytes(b"<html><head><title>t</title></head></html>")
    script = tmp_path / "s.js"
    script.write_bytes(b"window.x = 1;")
    root = resting_redraw.patched_root(build, script)
    assert root is not None and root.parent == tmp_path
    want = b"<html><head><script>window.x = 1;</script><title>t</title></head></html>"
    assert (root / "index.html").read_bytes() == want
    (root / "index.html").write_bytes(b"damaged")
    assert resting_redraw.patched_root(build, script) == root
    assert (root / "index.html").read_bytes() == want
    script.write_bytes(b"window.x = 2;")
    other = resting_redraw.patched_root(build, script)
    assert other is not None and other != root
