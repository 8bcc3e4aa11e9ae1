"""A still console page draws nothing: viser's once-a-second redraw rests while nothing happens.

viser 1.1.1's client draws its 3D view on demand (each server message opens 250 ms of frames)
and also once a second as a safety net (``RENDER_HEARTBEAT_MS`` in its ``App.tsx``). A browser
without a GPU draws those frames in software: a bare viser page costs 0.14 core with that
heartbeat and 0.02 without it, a still console ~0.2 (``benchmarks/page_busy.py``, 2026-12-06).

:func:`install` makes every ``ViserServer`` built afterwards serve viser's own page with one
script first in its ``<head>``, ``static/resting_redraw.js``: it lets the heartbeat fire only
within 3 s of the last server message that draws, of the operator's input or of a resize, so
the safety net still covers a change's late parts (a texture, a font: viser's own settle after a
message is 250 ms) and a still page draws nothing. Nothing else of viser's page changes
(:func:`patched_page` inserts the script and nothing else; the tests check both).

How it is served: viser's websocket server serves files from ``WebsockServer._http_server_root``
(its package's ``client/build``, read when the server starts), so the patch wraps
``WebsockServer.start``: a server whose root is viser's build is pointed at a folder holding the
patched page (named by a hash of its bytes, in the temporary directory, written once). Should
viser's build not be the single ``index.html`` with a ``<head>`` it was tested with, nothing is
swapped and a warning is logged: the page then keeps viser's heartbeat (busier, never wrong).
"""

from __future__ import annotations

import functools
import hashlib
import logging
import os
import tempfile
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

SCRIPT_PATH = Path(__file__).resolve().parents[2] / "static" / "resting_redraw.js"
_MARK = "_console_resting_redraw"  # on WebsockServer: its own start()
_HEAD = b"<head>"


def viser_build() -> Path:
    """viser's client build folder (what its servers serve)."""
    import viser

    return Path(viser.__file__).resolve().parent / "client" / "build"


def patched_page(page: bytes, script: bytes) -> bytes:
    """``page`` with ``<script>`` ``script`` ``</script>`` right after its first ``<head>``.

    Raises:
        ValueError: ``page`` has no ``<head>``.
    """
    at = page.find(_HEAD)
    if at < 0:
        raise ValueError("viser's client page has no <head>")
    at += len(_HEAD)
    return page[:at] + b"<script>" + script + b"</script>" + page[at:]


def patched_root(build: Path | None = None, script_path: Path = SCRIPT_PATH) -> Path | None:
    """A folder serving ``build``'s page with the resting-redraw script, or None if ``build`` is
    not the single ``index.html`` with a ``<head>`` the patch knows (a warning says why)."""
    build = viser_build() if build is None else build
    try:
        files = sorted(p.name for p in build.iterdir())
        if files != ["index.html"]:
            raise ValueError(f"viser's client build holds {files}, not index.html alone")
        page = patched_page((build / "index.html").read_bytes(), script_path.read_bytes())
        digest = hashlib.sha256(page).hexdigest()[:16]
        root = Path(tempfile.gettempdir()) / f"softarm-viser-page-{os.getuid()}-{digest}"
        target = root / "index.html"
        if not (target.is_file() and target.read_bytes() == page):
            root.mkdir(mode=0o700, exist_ok=True)
            part = root / f"index.html.{os.getpid()}"
            part.write_bytes(page)
            os.replace(part, target)
    except (OSError, ValueError) as exc:
        log.warning("viser's page is served as built, redrawing once a second (%s)", exc)
        return None
    return root

def install() -> bool:
    """Servers started from now on serve viser's page with the resting-redraw script.

    Wraps ``viser.infra._infra.WebsockServer.start`` (upstream 1.1.1: serves
    ``_http_server_root`` as given).

    Returns:
        True if it patched now, False if it was already installed.
    """
    from viser.infra import _infra

    cls: Any = _infra.WebsockServer
    if hasattr(cls, _MARK):
        return False
    original = cls.start

    @functools.wraps(original)
    def start(self: Any) -> None:
        root = getattr(self, "_http_server_root", None)
        if root is not None and Path(root).resolve() == viser_build():
            patched = patched_root()
            if patched is not None:
                self._http_server_root = patched
        original(self)

    setattr(cls, _MARK, original)
    cls.start = start
    return True


def installed() -> bool:
    """Whether :func:`install` is in place."""
    from viser.infra import _infra

    return hasattr(_infra.WebsockServer, _MARK)


def uninstall() -> bool:
    """Servers started from now on serve viser's page as built (tests); True if it was patched."""
    from viser.infra import _infra

    cls: Any = _infra.WebsockServer
    if not hasattr(cls, _MARK):
        return False
    cls.start = getattr(cls, _MARK)
    delattr(cls, _MARK)
    return True
