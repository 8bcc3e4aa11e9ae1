"""The load benchmark's clients: headless Chromium pages or websocket-only viewers."""

from __future__ import annotations

import argparse
import threading
from pathlib import Path

CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]


def chromium_path(a: argparse.Namespace) -> str:
    """Chromium, or a wrapper starting it in the idle scheduling class (``chrt --idle 0``) so
    that on this shared machine the browsers take only the CPU the console does not need (on
    the lab network they run elsewhere). Children inherit the class; Chromium's own re-nicing
    of its renderers does not leave it."""
    if a.browser_sched == "normal":
        return "/usr/bin/chromium"
    wrapper = Path(a.data_dir) / "chromium-idle.sh"
    wrapper.parent.mkdir(parents=True, exist_ok=True)
    wrapper.write_text('#!/bin/sh\nexec chrt --idle 0 /usr/bin/chromium "$@"\n')
    wrapper.chmod(0o755)
    return str(wrapper)


def ws_viewer(url: str, stop: threading.Event, received: list[int], i: int) -> None:
    """A websocket-only viewer: registers like a browser (one camera message), then receives
    everything the console streams and throws it away (no decoding, no rendering)."""
    import msgspec
    import viser
    from viser import _messages
    from websockets.sync.client import connect

    cam = _messages.ViewerCameraMessage((1.0, 0.0, 0.0, 0.0), (1.0, 1.0, 1.0), 1.0, 0.01, 100.0,
                                        480, 640, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    hello = msgspec.msgpack.encode(cam.as_serializable_dict())
    with connect(url.replace("http://", "ws://"), max_size=None,
                 subprotocols=[f"viser-v{viser.__version__}"]) as ws:  # type: ignore[list-item]
        ws.send(hello)
        while not stop.is_set():
            try:
                received[i] += len(ws.recv(timeout=0.5))
            except TimeoutError:
                continue
