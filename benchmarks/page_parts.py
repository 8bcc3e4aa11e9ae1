"""What each part of a still console's 3D scene costs a browser without a GPU, part by part.

``python benchmarks/page_parts.py [--robot soft-arm] [--seconds 15] [PREFIX ...]``

viser's client redraws the 3D view once a second even when nothing changes (its render
heartbeat), so a still page's CPU is that one frame a second, and what a frame costs in
software-rendered WebGL is the pixels each part covers times its shading. Builds the whole
console in this process (``serve.build``, the mock device, as ``page_busy.py`` serves it), opens
it in headless Chromium (``page_busy``'s flags, ``?fixedDpr=0.5``, 1600x1000), measures the
Chromium processes' CPU and the frames drawn, then hides the scene nodes under each ``PREFIX``
in turn (cumulatively) and measures again: each row's drop is that part's cost. Without
prefixes it prints the scene's node names. Prints a bare viser server's page first (the same
run's baseline; in this process it carries the console's patches, which leave a server without
the console's client guard deaf to its browser: a still page costs the same). Repeated runs
differ by ~0.03 core a row here: compare parts, not digits.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))


def cost(page: Any, seconds: float) -> tuple[float, float]:
    """(Chromium CPU s/s, frames/s) of ``page`` over ``seconds``, after 3 s to settle."""
    import page_busy as pb

    time.sleep(3.0)
    c0, t0 = pb._chromium_cpu(), time.monotonic()
    f0 = page.evaluate("() => window.__frames")
    time.sleep(seconds)
    dt = time.monotonic() - t0
    f1 = page.evaluate("() => window.__frames")
    return (pb._chromium_cpu() - c0) / dt, (f1 - f0) / dt


def open_page(pw: Any, url: str) -> tuple[Any, Any]:
    """(browser, page) at ``url``, loaded, with page_busy's frame counter."""
    import page_busy as pb

    browser = pw.chromium.launch(executable_path=pb.CHROMIUM, headless=True, args=pb.ARGS)
    context = browser.new_context(viewport={"width": 1600, "height": 1000})
    context.add_init_script(pb._COUNT_DRAWS)
    page = context.new_page()
    page.goto(url + "?fixedDpr=0.5")
    page.get_by_role("button", name="STOP (Esc)").wait_for(timeout=90_000)
    time.sleep(2.0)
    return browser, page


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robot", default="soft-arm")
    p.add_argument("--seconds", type=float, default=15.0)
    p.add_argument("--data-dir", default="/tmp/page_parts")
    p.add_argument("prefixes", nargs="*", help="scene node prefixes to hide, in turn")
    a = p.parse_args()

    import viser
    from playwright.sync_api import sync_playwright

    import bench_viewers as bv
    from core.robots import load

    serve = bv._serve_module()
    args = serve.parse_args(["--robot", a.robot, "--port", "0", "--no-token", "--hardware",
                             "mock", "--data-dir", a.data_dir, "--rt-cpu", "none"])
    server, app, _ = serve.build(args, load(a.robot), "page parts")
    app.start()
    nodes = server.scene._handle_from_node_name  # (a benchmark may read viser's table)
    try:
        if not a.prefixes:
            print("\n".join(sorted(nodes)))
            return 0
        with sync_playwright() as pw:
            bare = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
            try:
                bare.gui.add_button("STOP (Esc)")
                bare.scene.add_grid("/grid")
                browser, page = open_page(pw, f"http://127.0.0.1:{bare.get_port()}/")
                cpu, fps = cost(page, a.seconds)
                browser.close()
            finally:
                bare.stop()
            print(f"{'bare viser (button + grid)':40s} {cpu:6.3f} core  {fps:4.2f} frames/s")
            browser, page = open_page(pw, f"http://127.0.0.1:{server.get_port()}/")
            cpu, fps = cost(page, a.seconds)
            print(f"{a.robot + ': the whole scene':40s} {cpu:6.3f} core  {fps:4.2f} frames/s")
            for prefix in a.prefixes:
                hidden = 0
                for name in sorted(nodes):
                    handle = nodes[name]
                    if name.startswith(prefix) and handle.visible:
                        handle.visible = False
                        hidden += 1
                cpu2, fps = cost(page, a.seconds)
                print(f"{'  without ' + prefix + f' ({hidden} nodes)':40s} {cpu2:6.3f} core  "
                      f"{fps:4.2f} frames/s  (part: {cpu - cpu2:+.3f})")
                cpu = cpu2
            browser.close()
    finally:
        app.stop()
        server.stop()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
