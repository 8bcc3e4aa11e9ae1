"""Where one console page load's time goes in a browser without a GPU (what browser tests pay).

``python benchmarks/page_load.py [--robot soft-arm extensible] [--loads 2] [--repo A B] [-- FLAGS]``

Starts ``serve.py --robot NAME --hardware mock --no-token`` of each ``--repo`` checkout (default
this one) and measures:

- the connect on the wire: a raw websocket client (tests/ws_client's protocol) says hello and
  counts what the server sends until it has been without a frame for 0.3 s (the
  connect burst; the state stream goes on after it): frames, messages, bytes
  (compressed, as sent) and the biggest message types;
- ``--loads`` page loads in one headless Chromium (/usr/bin/chromium, the browser tests' flags,
  ``?fixedDpr=0.5``), each in a fresh context as the tests' ``page`` fixture makes them: from
  ``goto`` to DOMContentLoaded, to the first server message (the websocket is open), to the
  first scene node, to the STOP button visible (what
  tests/browser/browser_tabs.open_console waits for, via the Operate tab's panel); first
  the same for a bare viser server with just that button (viser's own floor). ("last msg" is
  the last message received up to 1.5 s after STOP shows: the state stream goes on.)

Everything runs one after the other, so two checkouts given in one call (``--repo /work/main .``)
are compared under the same machine load.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from benchmarks.page_busy import ARGS, CHROMIUM, _serve
from benchmarks.proc_figures import end_process

# Records when the page's viser worker passes on server messages (performance.now(), ms).
_TIMES = """(() => {
    window.__t = {first: null, scene: null, last: null, n: 0};
    const Worker0 = window.Worker;
    window.Worker = function (...args) {
        const worker = new Worker0(...args);
        worker.addEventListener("message", (e) => {
            const ms = (e.data && e.data.messages) || [];
            if (!ms.length) return;
            const now = performance.now();
            window.__t.n += ms.length;
            if (window.__t.first === null) window.__t.first = now;
            if (window.__t.scene === null && ms.some(m => /Mesh|Frame|Spline|Label|Grid/.test(m.type)))
                window.__t.scene = now;
            window.__t.last = now;
        });
        return worker;
    };
    window.Worker.prototype = Worker0.prototype;
})();"""


def _binary_indices(value: Any) -> list[int]:
    """The binary buffers a decoded message refers to (viser's ``__binary_index`` tags)."""
    if isinstance(value, dict):
        if "__binary_index" in value:
            return [int(value["__binary_index"])]
        return [i for v in value.values() for i in _binary_indices(v)]
    if isinstance(value, (list, tuple)):
        return [i for v in value for i in _binary_indices(v)]
    return []


def wire(url: str, gap: float = 0.3, limit: float = 20.0) -> dict[str, Any]:
    """What the server sends a new raw client until the first ``gap`` s without a frame (the
    connect burst; a live console keeps streaming state after it), at most ``limit`` s."""
    import msgspec
    import viser
    from viser import _messages
    from websockets.sync.client import connect

    from tests.ws_client import CAMERA, decode_payload, encode
    ws = connect(url.replace("http", "ws"), max_size=None, open_timeout=30,
                 subprotocols=[f"viser-v{viser.__version__}"])  # type: ignore[list-item]
    t0 = time.monotonic()
    ws.send(encode(CAMERA))
    frames = nbytes = 0
    last = first = t0
    kinds: Counter[str] = Counter()
    kind_bytes: Counter[str] = Counter()
    while time.monotonic() - t0 < limit:
        try:
            frame = ws.recv(timeout=gap if frames else limit)
        except TimeoutError:
            break
        last = time.monotonic()
        if not frames:
            first = last
        assert isinstance(frame, bytes)
        frames += 1
        nbytes += len(frame)
        payload = decode_payload(frame)
        lengths = payload.get("binaryBufferLengths") or []
        for m in payload["messages"]:
            kinds[m["type"]] += 1
            kind_bytes[m["type"]] += len(msgspec.msgpack.encode(m)) + sum(
                lengths[i] for i in _binary_indices(m))
        for m in payload["messages"]:  # answered like a browser tab (the operator's lease)
            if m["type"] == "LocalStorageGetItemRequestMessage":
                ws.send(encode(_messages.LocalStorageGetItemResponseMessage(
                    None, None, m["request_uuid"])))
    ws.close()
    return {"frames": frames, "messages": sum(kinds.values()), "bytes": nbytes,
            "burst_s": last - t0, "first_s": first - t0, "kinds": kinds, "kind_bytes": kind_bytes}


def load(browser: Any, url: str, timeout_ms: float = 120_000) -> dict[str, float]:
    """One page load in a fresh context: seconds from goto to each mark."""
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    context.add_init_script(_TIMES)
    page = context.new_page()
    try:
        t0 = time.monotonic()
        page.goto(url + "?fixedDpr=0.5")
        page.get_by_role("button", name="STOP (Esc)").wait_for(timeout=timeout_ms)
        page.get_by_role("tab", name="Operate", exact=True).wait_for(timeout=timeout_ms)
        stop = time.monotonic() - t0
        time.sleep(1.5)  # the connect burst's tail
        got = page.evaluate("""() => ({
            nav: performance.timeOrigin,
            dcl: performance.timing.domContentLoadedEventEnd - performance.timing.navigationStart,
            t: window.__t})""")
        t = got["t"]
        ms = 1e-3
        return {"dcl": got["dcl"] * ms, "ws": (t["first"] or 0) * ms,
                "scene": (t["scene"] or 0) * ms, "last": (t["last"] or 0) * ms,
                "stop": stop, "messages": t["n"]}
    finally:
        context.close()


def profile(browser: Any, url: str) -> dict[str, float]:
    """One load (goto to STOP visible) under the CDP sampling profiler: ms of the page's main
    thread by where it went (the HTML's inline script decodes viser's bundle, which viser
    1.1.1 ships inlined and compressed in index.html; the bundle then runs from an eval'd
    script without a URL; "(program)" is Chromium's own work: style, layout, paint, WebGL)."""
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    page = context.new_page()
    cdp = context.new_cdp_session(page)
    try:
        cdp.send("Profiler.enable")
        cdp.send("Profiler.setSamplingInterval", {"interval": 500})
        cdp.send("Profiler.start")
        page.goto(url + "?fixedDpr=0.5")
        page.get_by_role("button", name="STOP (Esc)").wait_for(timeout=120_000)
        prof = cdp.send("Profiler.stop")["profile"]
    finally:
        context.close()
    nodes = {n["id"]: n["callFrame"] for n in prof["nodes"]}
    spent: Counter[str] = Counter()
    for sample, dt in zip(prof["samples"], prof["timeDeltas"]):
        frame = nodes[sample]
        name, where = frame["functionName"], frame["url"]
        if name in ("(program)", "(garbage collector)", "(idle)"):
            key = name
        elif where.startswith("http"):
            key = "inline script: decode viser's bundle"
        elif where.startswith("wasm"):
            key = "wasm"
        else:
            key = "viser bundle (React, three.js)"
        spent[key] += dt / 1e3
    return dict(spent)


def floor(browser: Any, loads: int) -> list[float]:
    """viser's own floor: seconds from goto to a lone "STOP (Esc)" button of a bare viser
    server (one grid in the scene) -- the bundle's decode and start, three.js, the software
    WebGL context; what a console load costs beyond this is the console's content."""
    import viser
    srv = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        srv.gui.add_button("STOP (Esc)")
        srv.scene.add_grid("/grid")
        url = f"http://127.0.0.1:{srv.get_port()}/"
        out = []
        for _ in range(loads):
            context = browser.new_context(viewport={"width": 1280, "height": 800})
            try:
                page = context.new_page()
                t0 = time.monotonic()
                page.goto(url + "?fixedDpr=0.5")
                page.get_by_role("button", name="STOP (Esc)").wait_for(timeout=120_000)
                out.append(time.monotonic() - t0)
            finally:
                context.close()
        return out
    finally:
        srv.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", nargs="+", default=["soft-arm"])
    parser.add_argument("--loads", type=int, default=2)
    parser.add_argument("--repo", type=Path, nargs="+", default=[REPO])
    parser.add_argument("--no-browser", action="store_true", help="the wire figures only")
    parser.add_argument("--profile", action="store_true",
                        help="one more load under the CPU profiler: where the main thread went")
    parser.add_argument("extra", nargs="*", help="more serve.py flags (after --)")
    args = parser.parse_args()
    from playwright.sync_api import sync_playwright

    print(f"load average {os.getloadavg()[0]:.1f}")
    with sync_playwright() as pw:
        browser = None if args.no_browser else pw.chromium.launch(
            executable_path=CHROMIUM, headless=True, args=ARGS)
        try:
            if browser is not None:
                got = floor(browser, args.loads)
                print("bare viser (the floor): STOP " + ", ".join(f"{t:.2f}" for t in got)
                      + " s", flush=True)
            for repo in args.repo:
                for robot in args.robot:
                    proc, url = _serve(robot, args.extra, repo)
                    try:
                        time.sleep(5.0)  # serve.py answers HTTP before its panels exist
                        w = wire(url)
                        top = ", ".join(f"{k} {n}x {w['kind_bytes'][k] / 1e3:.0f} kB"
                                        for k, n in sorted(w["kinds"].items(),
                                                           key=lambda kv: -w["kind_bytes"][kv[0]])[:6])
                        print(f"{repo.name:10s} {robot:10s} wire: {w['frames']} frames, "
                              f"{w['messages']} messages, {w['bytes'] / 1e3:.0f} kB sent, "
                              f"first {w['first_s']:.2f} s, burst {w['burst_s']:.2f} s; by size: {top}", flush=True)
                        if browser is None:
                            continue
                        rows = [load(browser, url) for _ in range(args.loads)]
                        for r in rows:
                            print(f"{'':21s} load: DOMContentLoaded {r['dcl']:5.2f} s, ws "
                                  f"{r['ws']:5.2f}, scene {r['scene']:5.2f}, last msg "
                                  f"{r['last']:5.2f}, STOP {r['stop']:5.2f} s "
                                  f"({r['messages']} messages)", flush=True)
                        if args.profile:
                            spent = profile(browser, url)
                            print(f"{'':21s} profile (main thread, ms): " + ", ".join(
                                f"{k} {v:.0f}" for k, v in sorted(spent.items(),
                                                                  key=lambda kv: -kv[1])))
                        print(f"{'':21s} median STOP "
                              f"{statistics.median(r['stop'] for r in rows):.2f} s", flush=True)
                    finally:
                        end_process(proc)
        finally:
            if browser is not None:
                browser.close()


if __name__ == "__main__":
    main()
