"""What a viewer costs: bytes and updates per second per websocket viewer, still and moving,
the arm drawn by vertex streaming (``method="vertices"``, the original) and by pose
(``method="skinned"``, the default), side by side in one run; then 50 viewers on the new drawing
with the console's CPU and the control loop's p99.

``python benchmarks/bench_viewers.py [--seconds 10] [--viewers 50] [--robots soft-arm extensible]``

The first row is a bare viser page (a button and a grid) with the same viewer: the floor of a
still page (viser's own messages). Each (robot, method) runs the whole console in a child
process (``serve.build``: every panel, lab mode, the emulator, as ``serve.py`` serves it) with
websocket-only viewers (they register like a browser and count what arrives, without decoding
or rendering):

* still: the soft arm is armed and holds still on its control process, drawn from what the
  simulated motion capture measures (0.2 mm marker noise: ~0.8 mm / 1.7 deg at the tip); the
  extensible arm stands at a bent pose while a 100 Hz "motion capture" reports it with noise
  (tip ~0.05 mm rms). The console's dead band: 1 mm / 1 deg on frames averaged over 4 s while
  they jitter, 0.1 mm / 0.1 deg while they move steadily (``console.scene.dead_band.DeadBand``);
  ``benchmarks/viewer_messages.py`` lists every message a viewer of a still console gets;
* moving: the soft arm runs grasp-and-place trials back to back on its control process (the
  100 Hz loop in its own process, which publishes its period error p99); the extensible arm's
  demo motion (``console.core.demo_motion``) is reported at 100 Hz with the same noise (its loop is
  a thread of the console that publishes no p99).

Each child first waits for its start-up overlays (the soft arm's reachability map, printed with
how long it took), so that their one-off ~50 KB does not count as the cost of a still arm.
Bytes are websocket payload bytes as viser hands them to the socket (its zstd-compressed
msgpack plus raw arrays), what each viewer costs the network. Updates/s: websocket messages a
viewer received per second, and arm frames the console sent (``ArmView.frames_sent``).
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
sys.path.insert(0, str(REPO / "benchmarks"))

from proc_figures import cpu_seconds  # noqa: E402

GOALS = {"moving_kbps": 60.0, "moving_ups": 20.0, "still_kbps": 0.5, "p99_ms": 1.0,
         "cpu_pct": 50.0}
NOISE_HZ = 100.0
MOVING_GAP_S = 0.25  # a longer interval between two arm frames is a pause (see moving_rate)


# -- the console child ---------------------------------------------------------------------------

def _serve_module() -> Any:
    spec = importlib.util.spec_from_file_location("serve", REPO / "serve.py")
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    return module


def still_pose(model: Any) -> np.ndarray:
    """A bent pose the still phase holds (well inside the limits)."""
    if model.kind == "planar":
        return 0.5 * model.robot.kappa_max * np.array([1.0, -0.6, 0.8, 0.3, -0.9, 0.5])
    r = model.robot
    q = np.zeros(model.shape)
    q[:, 2] = 0.5 * (r.rack_min + r.rack_max) - r.L0
    q[0, 0], q[1, 1] = 0.015, -0.012
    return q


def noise_scale(view: Any, q0: np.ndarray, tip_rms: float = 5e-5) -> float:
    """Per-coordinate noise (1/m or m) that moves the drawn tip by ``tip_rms`` (m) rms."""
    rng = np.random.default_rng(1)
    tip0 = view.frames(q0)[-1, :3, 3]
    probe = 1e-6
    moves = [np.linalg.norm(view.frames(q0 + probe * rng.standard_normal(q0.shape))[-1, :3, 3]
                            - tip0) for _ in range(200)]
    return probe * tip_rms / float(np.sqrt(np.mean(np.square(moves))))


def start_mocap(app: Any, q0: np.ndarray, stop: threading.Event, moving: bool = False,
                seed: int = 0) -> threading.Thread:
    """Report ``q0`` (the demo motion while ``moving``) as "motion capture" at :data:`NOISE_HZ`,
    with noise that moves the drawn tip by 0.05 mm rms (:func:`noise_scale`), until ``stop``."""
    from console.core.demo_motion import demo_configuration

    scale = noise_scale(app.view, q0)
    rng = np.random.default_rng(seed)

    def run() -> None:
        t0 = time.monotonic()
        while not stop.wait(1.0 / NOISE_HZ):
            q = demo_configuration(app.model, time.monotonic() - t0) if moving else q0
            app.store.report(q + scale * rng.standard_normal(q0.shape), "mocap")

    thread = threading.Thread(target=run, name="bench-mocap", daemon=True)
    thread.start()
    return thread


def mocap_only(app: Any) -> None:
    """Draw only what the benchmark's "motion capture" reports (the extensible arm).

    The extensible arm's loop process reports what its emulator measures (~25 Hz, "runner")
    wherever the arm stands (it is not armed here, so it does not move to ``q0``): mixed with
    the benchmark's reports the drawn arm would jump between two poses every frame.
    """
    report = app.store.report

    def only_mocap(q: Any, source: str = "hardware") -> Any:
        return report(q, source) if source == "mocap" else app.store.display

    app.store.report = only_mocap


def bare_child() -> int:
    """Serve a bare viser page (a button and a grid, nothing moving): the floor a still console
    is compared with. Answers the same stdin commands as :func:`child` (``move`` does nothing)."""
    import viser

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    server.gui.add_button("STOP (Esc)")
    server.scene.add_grid("/grid")
    print(f"READY {server.get_port()} nan", flush=True)
    for line in sys.stdin:
        cmd = line.strip()
        if cmd == "still":
            print("STILL", flush=True)
        elif cmd == "stats":
            print(json.dumps({"frames_sent": 0, "sent_at": [], "now": time.monotonic(),
                              "frames_drawn": 0, "loop": None,
                              "clients": len(server.get_clients())}), flush=True)
        elif cmd == "quit":
            break
    server.stop()
    return 0


def child(a: argparse.Namespace) -> int:
    """Serve the console; stdin commands: ``still``, ``move``, ``stats``, ``quit``."""
    if a.method == "bare":
        return bare_child()
    from console.scene.arm_view_factory import make_arm_view
    from core.robots import load

    sys.path.insert(0, str(REPO / "benchmarks"))
    from load_trials import start_trials

    serve = _serve_module()
    robot = load(a.robot)
    args = serve.parse_args(["--robot", a.robot, "--port", "0", "--lab", "--no-token",
                             "--data-dir", a.data_dir, "--rt-cpu", a.rt_cpu])
    server, app, _ = serve.build(args, robot, "viewer benchmark")
    if a.method == "vertices":  # the original drawing: whole vertex arrays, every frame
        app.view = make_arm_view(server.scene, app.model, method="vertices", dead_band=None)
    app.start()
    stop_noise, stop_trials = threading.Event(), threading.Event()
    q0 = still_pose(app.model)

    ctl: Any = None
    # Start-up overlays (the reachability map) arrive once, some seconds after start: wait for
    # them, so that they do not count as the steady cost of a still arm.
    reach_s = float("nan")
    planner = next((p for p in app.panels if hasattr(p, "reach_note")), None)
    t_start = time.monotonic()
    while planner is not None and time.monotonic() - t_start < 120.0:
        if "computing" not in str(planner.reach_note.content):
            reach_s = time.monotonic() - t_start
            break
        time.sleep(0.2)
    soft = app.services.soft_control
    if soft is not None:  # armed and holding: the Control panel draws what it measures
        soft.arm().result(60)
    print(f"READY {server.get_port()} {reach_s:.1f}", flush=True)
    for line in sys.stdin:
        cmd = line.strip()
        if cmd == "still":
            if soft is None:
                mocap_only(app)
                app.store.request(q0, "bench")
                start_mocap(app, q0, stop_noise)
            print("STILL", flush=True)
        elif cmd == "move":
            stop_noise.set()
            time.sleep(0.1)
            ctl, _ = start_trials(app, robot, stop_trials)
            if ctl is None:  # no control process: "motion capture" of the demo motion
                start_mocap(app, q0, stop_trials, moving=True)
        elif cmd == "stats":
            view = None if ctl is None else ctl.view
            loop = None if view is None else {"p99_ms": view.stats.period_error_ms_p99,
                                              "max_ms": view.stats.period_error_ms_max}
            print(json.dumps({"frames_sent": app.view.frames_sent,
                              "sent_at": list(getattr(app.view, "sent_at", ())),
                              "now": time.monotonic(),
                              "frames_drawn": app.frames_drawn, "loop": loop,
                              "clients": len(server.get_clients())}), flush=True)
        elif cmd == "quit":
            break
    stop_noise.set()
    stop_trials.set()
    app.stop()
    app.services.close()
    server.stop()
    return 0


# -- the measuring parent ------------------------------------------------------------------------

def ws_viewer(url: str, stop: threading.Event, counts: list[list[int]], i: int) -> None:
    """A websocket-only viewer (``load_clients.ws_viewer``), counting bytes and messages."""
    import msgspec
    import viser
    from viser import _messages
    from websockets.exceptions import ConnectionClosed
    from websockets.sync.client import connect

    cam = _messages.ViewerCameraMessage((1.0, 0.0, 0.0, 0.0), (1.0, 1.0, 1.0), 1.0, 0.01, 100.0,
                                        480, 640, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    with connect(url, max_size=None, compression=None,
                 subprotocols=[f"viser-v{viser.__version__}"]) as ws:  # type: ignore[list-item]
        ws.send(msgspec.msgpack.encode(cam.as_serializable_dict()))
        while not stop.is_set():
            try:
                counts[i][0] += len(ws.recv(timeout=0.5))
                counts[i][1] += 1
            except TimeoutError:
                continue
            except ConnectionClosed:  # the console stopped at the end of its phase
                return


class Console:
    """A console child process and its viewers."""

    def __init__(self, a: argparse.Namespace, robot: str, method: str) -> None:
        cmd = [sys.executable, __file__, "--child", "--robot", robot, "--method", method,
               "--data-dir", a.data_dir, "--rt-cpu", a.rt_cpu]
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     text=True, cwd=REPO)
        line = ""
        while not line.startswith("READY"):
            line = self.proc.stdout.readline()  # type: ignore[union-attr]
            if not line:
                raise RuntimeError("console child ended before READY")
        self.url = f"ws://127.0.0.1:{line.split()[1]}"
        self.reach_s = float(line.split()[2])
        self.stop = threading.Event()
        self.counts: list[list[int]] = []
        self.threads: list[threading.Thread] = []

    def send(self, cmd: str) -> None:
        self.proc.stdin.write(cmd + "\n")  # type: ignore[union-attr]
        self.proc.stdin.flush()  # type: ignore[union-attr]

    def wait_for(self, word: str) -> None:
        while True:
            line = self.proc.stdout.readline()  # type: ignore[union-attr]
            if not line:
                raise RuntimeError(f"console child ended before {word}")
            if line.startswith(word):
                return

    def stats(self) -> dict[str, Any]:
        self.send("stats")
        return json.loads(self.proc.stdout.readline())  # type: ignore[union-attr]

    def add_viewers(self, n: int) -> None:
        for _ in range(n):
            self.counts.append([0, 0])
            th = threading.Thread(target=ws_viewer, daemon=True,
                                  args=(self.url, self.stop, self.counts, len(self.counts) - 1))
            th.start()
            self.threads.append(th)
        deadline = time.monotonic() + 30.0
        while self.stats()["clients"] < len(self.counts) and time.monotonic() < deadline:
            time.sleep(0.2)

    def measure(self, seconds: float) -> dict[str, Any]:
        """Per-viewer bytes/s and messages/s, arm frames/s, console CPU over ``seconds``."""
        c0, s0, t0 = [list(c) for c in self.counts], self.stats(), time.monotonic()
        cpu0 = cpu_seconds(self.proc.pid)
        time.sleep(seconds)
        c1, s1, dt = [list(c) for c in self.counts], self.stats(), time.monotonic() - t0
        cpu = (cpu_seconds(self.proc.pid) - cpu0) / dt
        per = np.array([[(b[0] - a[0]) / dt, (b[1] - a[1]) / dt] for a, b in zip(c0, c1)])
        sent = np.array([t for t in s1["sent_at"] if t > s0["now"]])
        moving_ups, moving_share = moving_rate(sent, s1["now"] - s0["now"])
        return {"kbps": float(per[:, 0].mean()) / 1000.0, "msgs": float(per[:, 1].mean()),
                "frames": (s1["frames_sent"] - s0["frames_sent"]) / dt,
                "moving_ups": moving_ups, "moving_share": moving_share,
                "cpu_pct": 100.0 * cpu, "loop": s1["loop"], "viewers": len(per)}

    def close(self) -> None:
        self.stop.set()
        try:
            self.send("quit")
            self.proc.wait(15)
        except Exception:  # noqa: BLE001 - a child that hangs is ended
            self.proc.kill()
        for th in self.threads:
            th.join(2)


def moving_rate(sent_at: np.ndarray, span: float, gap: float = MOVING_GAP_S,
                ) -> tuple[float, float]:
    """Arm frames per second while the arm moves, and the share of ``span`` it moved.

    A grasp-and-place trial holds the arm still for seconds (settling, planning, closing the
    gripper), when the dead band rightly sends nothing: frames sent / time would mix those
    pauses into the rate. "Moving" is every interval between two sent frames of at most
    ``gap`` seconds (a longer one is a pause; the display at 30 Hz with a 0.5 mm band sends
    a move faster than 2 mm/s more often than that); the rate is their count over their sum.
    """
    steps = np.diff(np.sort(sent_at))
    moving = steps[steps <= gap]
    if len(moving) == 0 or span <= 0:
        return 0.0, 0.0
    return float(len(moving) / moving.sum()), float(min(moving.sum() / span, 1.0))


def run(a: argparse.Namespace, robot: str, method: str, many: int) -> dict[str, Any]:
    console = Console(a, robot, method)
    try:
        console.add_viewers(1)
        console.send("still")
        console.wait_for("STILL")
        time.sleep(a.warmup)
        still = console.measure(a.seconds)
        if method == "bare":
            return {"still": still, "moving": None, "crowd": None, "reach_s": float("nan")}
        console.send("move")
        time.sleep(a.warmup + (5.0 if robot == "soft-arm" else 0.0))  # arm + first plan
        moving = console.measure(a.seconds)
        crowd = None
        if many:
            console.add_viewers(many - 1)
            time.sleep(a.warmup)
            crowd = console.measure(a.seconds)
        return {"still": still, "moving": moving, "crowd": crowd, "reach_s": console.reach_s}
    finally:
        console.close()


def fmt_loop(m: dict[str, Any] | None) -> str:
    if m is None:
        return "-"
    loop = m["loop"]
    return "n/a" if loop is None else f"{loop['p99_ms']:.3f}"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--robot", default="soft-arm", help=argparse.SUPPRESS)
    p.add_argument("--method", default="skinned", help=argparse.SUPPRESS)
    p.add_argument("--robots", nargs="+", default=["soft-arm", "extensible"])
    p.add_argument("--seconds", type=float, default=10.0, help="each measured phase (s)")
    p.add_argument("--warmup", type=float, default=2.0, help="before each phase (s)")
    p.add_argument("--viewers", type=int, default=50, help="viewers of the crowd phase")
    p.add_argument("--data-dir", default="/tmp/bench_viewers")
    p.add_argument("--rt-cpu", choices=("auto", "none"), default="auto")
    a = p.parse_args()
    if a.child:
        return child(a)
    rows = [("bare viser", "bare", run(a, "bare viser", "bare", 0))]
    print("bare viser done", file=sys.stderr, flush=True)
    for robot in a.robots:
        for method in ("vertices", "skinned"):
            # 50 viewers of the vertex stream would need ~50 MB/s: the crowd runs the new drawing.
            r = run(a, robot, method, a.viewers if method == "skinned" else 0)
            rows.append((robot, method, r))
            print(f"{robot:10s} {method:8s} done", file=sys.stderr, flush=True)
    print(f"\nOne viewer ({a.seconds:.0f} s per phase; KB = 1000 bytes of websocket payload)")
    print(f"{'robot':10s} {'method':8s} | {'moving KB/s':>11s} {'msg/s':>6s} {'frames/s':>8s} "
          f"{'moving f/s':>10s} {'moved':>5s} | {'still KB/s':>10s} {'msg/s':>6s} "
          f"{'frames/s':>8s}")
    for robot, method, r in rows:
        m, s = r["moving"], r["still"]
        moving = (f"{'-':>11s} {'-':>6s} {'-':>8s} {'-':>10s} {'-':>5s}" if m is None else
                  f"{m['kbps']:11.1f} {m['msgs']:6.1f} {m['frames']:8.1f} "
                  f"{m['moving_ups']:10.1f} {100 * m['moving_share']:4.0f}%")
        print(f"{robot:10s} {method:8s} | {moving} | "
              f"{s['kbps']:10.2f} {s['msgs']:6.1f} {s['frames']:8.1f}")
    print(f"goal (skinned)      | {'<= ' + str(GOALS['moving_kbps']):>11s} {'':6s} {'':8s} "
          f"{'>= ' + str(GOALS['moving_ups']):>10s} {'':5s} | "
          f"{'<= ' + str(GOALS['still_kbps']):>10s}")
    print("(frames/s: arm frames sent over the whole phase; moving f/s: while the arm moved, "
          f"i.e. over intervals between frames <= {MOVING_GAP_S} s, which cover 'moved' of "
          "the phase: trials pause to settle, plan and grip)")
    print(f"\n{a.viewers} viewers, arm moving (skinned)")
    print(f"{'robot':10s} | {'KB/s/viewer':>11s} {'frames/s':>8s} {'moving f/s':>10s} "
          f"{'console CPU %':>13s} {'loop p99 ms':>11s}")
    for robot, method, r in rows:
        c = r["crowd"]
        if c is not None:
            print(f"{robot:10s} | {c['kbps']:11.1f} {c['frames']:8.1f} {c['moving_ups']:10.1f} "
                  f"{c['cpu_pct']:13.1f} {fmt_loop(c):>11s}")
    print(f"goal       | {'<= ' + str(GOALS['moving_kbps']):>11s} {'':8s} "
          f"{'>= ' + str(GOALS['moving_ups']):>10s} {'<= ' + str(GOALS['cpu_pct']):>13s} "
          f"{'<= ' + str(GOALS['p99_ms']):>11s}")
    print("(loop p99: the soft arm's 100 Hz control process, period error; the extensible "
          "arm's loop publishes none: n/a)")
    for robot, method, r in rows:
        if r["reach_s"] == r["reach_s"]:
            print(f"reachability overlay of {robot} ({method} run) ready {r['reach_s']:.1f} s "
                  "after the console was built (waited for before measuring)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
