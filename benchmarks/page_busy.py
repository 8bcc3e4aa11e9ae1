"""How busy a still console keeps a browser without a GPU: CPU, frames drawn and messages received.

``python benchmarks/page_busy.py [--robot soft-arm extensible] [--repo CHECKOUT ...] [--armed]``

Starts ``serve.py --robot NAME --hardware mock --no-token`` of each ``--repo`` checkout (default
this one) on a free port (``--armed``: instead builds the whole console on the emulator in this
process, the soft arm armed and holding still, the extensible arm under mocap noise), opens it in
headless Chromium (/usr/bin/chromium with the browser tests' flags: ``--disable-gpu``, so WebGL
is drawn in software, and ``?fixedDpr=0.5``) as its operator, lets the page settle (and rest:
``console.web.resting_redraw``), then over ``--seconds`` counts what the still page costs: the
CPU seconds of every Chromium process (renderer and the software-GL GPU process, from /proc),
the renderer's task and script time (CDP ``Performance.getMetrics``), the 3D frames drawn
(animation frames with a WebGL draw call, counted by a wrapper on the context) and the server's
messages the page received, by type; first the same for a bare viser server with one button
and a grid, as viser serves it and with the console's resting redraw (viser's own floor, in the
same run). Everything runs one after the other: give both robots and two checkouts
(``--repo /path/to/main .``) in one call to compare them under the same load.
"""

from __future__ import annotations

import argparse
import os
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from proc_figures import descendants, end_process  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
CHROMIUM = "/usr/bin/chromium"
ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--disable-sync", "--no-first-run"]

# Counts WebGL draw calls and the frames in which any was made: a frame's draws are one task
# (three.js renders synchronously), so the first draw counts a frame and a microtask after the
# task ends the frame. (It used to count them with its own requestAnimationFrame loop, which
# kept Chromium producing 60 frames/s and cost 0.09 core of the figures it measured.)
_COUNT_DRAWS = """(() => {
    window.__draws = 0; window.__frames = 0; let drew = false;
    const frameEnds = () => { drew = false; };
    for (const proto of [WebGLRenderingContext.prototype, WebGL2RenderingContext.prototype]) {
        for (const name of ["drawElements", "drawArrays", "drawElementsInstanced",
                            "drawArraysInstanced"]) {
            const f = proto[name];
            if (!f) continue;
            proto[name] = function (...a) {
                window.__draws++;
                if (!drew) { drew = true; window.__frames++; queueMicrotask(frameEnds); }
                return f.apply(this, a);
            };
        }
    }
    // viser's websocket lives in a worker: count the server's messages the worker passes on.
    window.__messages = {};
    const Worker0 = window.Worker;
    window.Worker = function (...args) {
        const worker = new Worker0(...args);
        worker.addEventListener("message", (e) => {
            for (const m of (e.data && e.data.messages) || []) {
                window.__messages[m.type] = (window.__messages[m.type] || 0) + 1;
            }
        });
        return worker;
    };
    window.Worker.prototype = Worker0.prototype;
})();"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _serve(robot: str, extra: list[str], repo: Path = REPO) -> tuple[subprocess.Popen[bytes], str]:
    port = _free_port()
    proc = subprocess.Popen(
        [sys.executable, str(repo / "serve.py"), "--robot", robot, "--host", "127.0.0.1",
         "--port", str(port), "--hardware", "mock", "--no-token", *extra],
        cwd=repo, env={**os.environ, "PYTHONPATH": str(repo)}, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    url = f"http://127.0.0.1:{port}/"
    deadline = time.monotonic() + 90
    while time.monotonic() < deadline:
        try:
            with urllib.request.urlopen(url, timeout=1.0) as resp:
                if resp.status == 200:
                    return proc, url
        except OSError:
            time.sleep(0.2)
    proc.kill()
    raise SystemExit(f"serve.py --robot {robot} did not serve {url}")


def _chromium_cpu() -> float:
    """CPU seconds (user + system) of the Chromium processes under this one."""
    tick = os.sysconf("SC_CLK_TCK")
    total = 0.0
    for pid in descendants(os.getpid())[1:]:
        try:
            stat = Path(f"/proc/{pid}/stat").read_text()
            if "(chrom" not in stat:
                continue
            fields = stat.rsplit(")", 1)[1].split()
        except OSError:
            continue
        total += (int(fields[11]) + int(fields[12])) / tick
    return total


def measure(pw: Any, robot: str, settle: float, seconds: float, shot: Path | None,
            extra: list[str], repo: Path = REPO) -> dict[str, Any]:
    """One robot's still page: returns the figures printed by :func:`main`."""
    proc, url = _serve(robot, extra, repo)
    try:
        return measure_page(pw, url, settle, seconds, shot)
    finally:
        end_process(proc)


def measure_armed(pw: Any, robot_name: str, settle: float, seconds: float, shot: Path | None,
                  data_dir: Path) -> dict[str, Any]:
    """The same for the whole console on the emulator, built in this process as
    ``viewer_messages.py`` builds it: the soft arm armed and holding still on its control process
    (under the simulated motion capture's noise), the extensible arm at a bent pose with 100 Hz
    "motion capture" noise of 0.05 mm at the tip."""
    import threading

    import bench_viewers as bv
    from core.robots import load

    serve = bv._serve_module()
    robot = load(robot_name)
    port = _free_port()
    args = serve.parse_args(["--robot", robot_name, "--host", "127.0.0.1", "--port", str(port),
                             "--no-token", "--data-dir", str(data_dir), "--rt-cpu", "none"])
    server, app, _ = serve.build(args, robot, "page busy")
    app.start()
    stop = threading.Event()
    try:
        soft = app.services.soft_control
        if soft is not None:
            soft.arm().result(60)
        else:
            q0 = bv.still_pose(app.model)
            bv.mocap_only(app)
            app.store.request(q0, "bench")
            bv.start_mocap(app, q0, stop)
        return measure_page(pw, f"http://127.0.0.1:{port}/", settle, seconds, shot)
    finally:
        stop.set()
        app.stop()
        app.services.close()
        server.stop()


def measure_bare(pw: Any, settle: float, seconds: float, resting: bool = False
                 ) -> dict[str, Any]:
    """The same for a bare viser server with a "STOP (Esc)" button and a grid (viser's own
    floor: what any still viser page costs this browser); ``resting``: its page served with
    the console's resting redraw (``console.web.resting_redraw``)."""
    import viser

    from console.web import resting_redraw

    patched = resting and resting_redraw.install()
    try:
        srv = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    finally:
        if patched:
            resting_redraw.uninstall()
    try:
        srv.gui.add_button("STOP (Esc)")
        srv.scene.add_grid("/grid")
        return measure_page(pw, f"http://127.0.0.1:{srv.get_port()}/", settle, seconds, None)
    finally:
        srv.stop()


def measure_page(pw: Any, url: str, settle: float, seconds: float, shot: Path | None
                 ) -> dict[str, Any]:
    """A still page at ``url`` (served until it returns) as its first browser."""
    browser = pw.chromium.launch(executable_path=CHROMIUM, headless=True, args=ARGS)
    try:
        context = browser.new_context(viewport={"width": 1600, "height": 1000})
        context.add_init_script(_COUNT_DRAWS)
        page = context.new_page()
        cdp = context.new_cdp_session(page)
        cdp.send("Performance.enable")
        page.goto(url + "?fixedDpr=0.5")
        page.get_by_role("button", name="STOP (Esc)").wait_for(timeout=90_000)
        time.sleep(settle)
        for notice in page.locator(".mantine-Notification-root").all():
            try:
                notice.locator("button").first.click(timeout=2_000)
            except Exception:  # noqa: BLE001, S110 - closed by itself meanwhile
                pass
        # Those clicks are the operator's input: the console's page redraws for its rest time
        # after them (console/web/resting_redraw.py), so the still page is measured after it.
        rest_ms = page.evaluate("() => (window.__restingRedraw || {}).restAfterMs || 0")
        time.sleep(2.0 + float(rest_ms) / 1000.0)

        def metrics() -> dict[str, float]:
            got = cdp.send("Performance.getMetrics")["metrics"]
            return {m["name"]: float(m["value"]) for m in got}

        m0, cpu0, t0 = metrics(), _chromium_cpu(), time.monotonic()
        d0 = page.evaluate("() => [window.__draws, window.__frames, {...window.__messages}]")
        time.sleep(seconds)
        m1, cpu1, t1 = metrics(), _chromium_cpu(), time.monotonic()
        d1 = page.evaluate("() => [window.__draws, window.__frames, {...window.__messages}]")
        dt = t1 - t0
        if shot is not None:
            page.screenshot(path=str(shot))
        return {
            "chromium_cpu": (cpu1 - cpu0) / dt,
            "task": (m1["TaskDuration"] - m0["TaskDuration"]) / dt,
            "script": (m1["ScriptDuration"] - m0["ScriptDuration"]) / dt,
            "frames_per_s": (d1[1] - d0[1]) / dt,
            "draws_per_frame": (d1[0] - d0[0]) / max(1, d1[1] - d0[1]),
            "messages": {k: (n - d0[2].get(k, 0)) / dt for k, n in d1[2].items()
                         if n > d0[2].get(k, 0)},
        }
    finally:
        browser.close()


def _print(checkout: str, robot: str, r: dict[str, Any]) -> None:
    print(f"{checkout:10s} {robot:12s} {r['chromium_cpu']:16.2f}  {r['task']:8.2f}"
          f"  {r['script']:10.2f}  {r['frames_per_s']:8.1f}  "
          f"{r['draws_per_frame']:11.0f}", flush=True)
    messages = sorted(r["messages"].items(), key=lambda kv: -kv[1])
    print("    messages/s: " + (", ".join(f"{k} {v:.1f}" for k, v in messages) or "none"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", nargs="+", default=["soft-arm", "extensible"])
    parser.add_argument("--settle", type=float, default=8.0, help="s after STOP shows")
    parser.add_argument("--seconds", type=float, default=10.0, help="s measured")
    parser.add_argument("--shots", type=Path, default=None, help="folder for a PNG per robot")
    parser.add_argument("--repo", type=Path, nargs="+", default=[REPO],
                        help="checkouts whose serve.py to run, in turn (compare two versions)")
    parser.add_argument("--armed", action="store_true",
                        help="the console on the emulator (built in this process), the soft "
                             "arm armed and holding, the extensible arm under mocap noise")
    parser.add_argument("extra", nargs="*", help="more serve.py flags (after --)")
    args = parser.parse_args()
    from playwright.sync_api import sync_playwright

    print(f"load {os.getloadavg()[0]:.1f}")
    print("checkout   robot        Chromium CPU s/s  task s/s  script s/s  frames/s  draws/frame")
    with sync_playwright() as pw:
        _print("bare viser", "(button+grid)", measure_bare(pw, args.settle, args.seconds))
        _print("bare viser", "+ resting", measure_bare(pw, args.settle, args.seconds, True))
        for repo in args.repo:
            for robot in args.robot:
                shot = None
                if args.shots is not None:
                    args.shots.mkdir(parents=True, exist_ok=True)
                    shot = args.shots / f"{repo.name}-{Path(robot).stem}.png"
                if args.armed:
                    import tempfile
                    with tempfile.TemporaryDirectory() as data_dir:
                        _print(repo.name, f"{robot} armed", measure_armed(
                            pw, robot, args.settle, args.seconds, shot, Path(data_dir)))
                    continue
                _print(repo.name, robot,
                       measure(pw, robot, args.settle, args.seconds, shot, args.extra, repo))


if __name__ == "__main__":
    main()
