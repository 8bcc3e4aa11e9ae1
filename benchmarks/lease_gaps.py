"""How long a real browser stays silent: the data the operator lease's limits come from.

``python benchmarks/lease_gaps.py [--seconds 20] [--hog 2] [--tablet] [--loads 3]``

Builds the whole console in this process (``serve.build``: every panel, desk mode, mock
hardware, the demo motion streaming the arm to the browser as a running plan does) with the
lease limits raised out of the way, opens it in headless Chromium (software rendering, the
browser tests' flags) and records, server side, every answer of the lease probe
(``AccessControl.heartbeat``) -- exactly the signal the lease judges:

* load: seconds from the websocket connect to the tab's first answer (the page building the
  console), for ``--loads`` fresh tabs;
* run: the gaps between consecutive answers while the arm moves, for ``--seconds`` s.

``--hog N`` runs N busy-loop processes (``while 1: pass``) meanwhile; ``--tablet`` emulates a
tablet: an 820x1180 touch viewport and 4x CPU throttling (CDP ``Emulation.setCPUThrottlingRate``).
Prints one JSON line of percentiles (s).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]


def _serve_module() -> Any:
    spec = importlib.util.spec_from_file_location("serve", REPO / "serve.py")
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    return module


class Answers:
    """Server-side log: connect time per client and the time of each of its probe answers."""

    def __init__(self, app: Any) -> None:
        self.lock = threading.Lock()
        self.connected: dict[int, float] = {}
        self.heard: dict[int, list[float]] = {}
        access = app.access
        original = access.heartbeat

        def heartbeat(client: Any) -> bool:
            ok = original(client)
            if ok:
                with self.lock:
                    self.heard.setdefault(int(client), []).append(time.monotonic())
            return ok

        access.heartbeat = heartbeat  # type: ignore[method-assign]
        app.server.on_client_connect(self._connect)

    def _connect(self, client: Any) -> None:
        with self.lock:
            self.connected[client.client_id] = time.monotonic()


def pct(values: list[float]) -> dict[str, float]:
    if not values:
        return {}
    a = np.asarray(values)
    return {"n": int(a.size), "p50": round(float(np.percentile(a, 50)), 3),
            "p99": round(float(np.percentile(a, 99)), 3),
            "p99.9": round(float(np.percentile(a, 99.9)), 3), "max": round(float(a.max()), 3)}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=20.0)
    p.add_argument("--hog", type=int, default=0)
    p.add_argument("--tablet", action="store_true")
    p.add_argument("--loads", type=int, default=3)
    opts = p.parse_args()

    serve = _serve_module()
    args = serve.parse_args(["--robot", "soft-arm", "--host", "127.0.0.1", "--port", "0",
                             "--hardware", "mock", "--demo", "--no-token",
                             "--data-dir", "/tmp/lease-gaps-runs"])
    server, app, _ = serve.build(args, serve.load("soft-arm"), "lease gaps")
    app.access.lease_s, app.access.first_answer_s = 600.0, 600.0  # measure, never revoke
    answers = Answers(app)
    app.start()
    url = f"http://127.0.0.1:{server.get_port()}/"
    hogs = [subprocess.Popen([sys.executable, "-c", "while 1: pass"]) for _ in range(opts.hog)]
    from playwright.sync_api import sync_playwright

    loads: list[float] = []
    gaps: list[float] = []
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path="/usr/bin/chromium", headless=True,
                                         args=CHROMIUM_ARGS)
            view = ({"width": 820, "height": 1180} if opts.tablet
                    else {"width": 1280, "height": 800})
            for i in range(opts.loads):
                context = browser.new_context(viewport=view, has_touch=opts.tablet,
                                              is_mobile=opts.tablet)
                page = context.new_page()
                if opts.tablet:
                    context.new_cdp_session(page).send("Emulation.setCPUThrottlingRate",
                                                       {"rate": 4})
                with answers.lock:
                    known = set(answers.connected)
                page.goto(url)
                deadline = time.monotonic() + 120
                while time.monotonic() < deadline:
                    with answers.lock:
                        new = set(answers.connected) - known
                        cid = max(new, default=None)
                        first = answers.heard.get(cid, []) if cid is not None else []
                        if cid is not None and first:
                            loads.append(first[0] - answers.connected[cid])
                            break
                    time.sleep(0.05)
                if i < opts.loads - 1:
                    context.close()
                    time.sleep(0.5)
            # the last tab stays: the arm moves (the demo streams it) while we listen
            page.get_by_text("Grasp planner", exact=True).wait_for(timeout=120_000)
            if app.services.demo is not None:
                app.services.demo.start()
            frames0 = app.view.frames_sent if hasattr(app.view, "frames_sent") else None
            with answers.lock:
                cid = max(answers.connected)
                start = len(answers.heard.get(cid, []))
            time.sleep(opts.seconds)
            with answers.lock:
                times = answers.heard.get(cid, [])[start:]
            gaps = list(np.diff(times))
            frames = (app.view.frames_sent - frames0) if frames0 is not None else None
            browser.close()
    finally:
        for h in hogs:
            h.kill()
        app.stop()
        server.stop()
    print(json.dumps({"hog": opts.hog, "tablet": opts.tablet, "load_first_answer": pct(loads),
                      "loads": [round(x, 2) for x in loads], "run_gap": pct(gaps),
                      "arm_frames_sent": frames, "probe_period": app.lease.probe_period}))


if __name__ == "__main__":
    main()
