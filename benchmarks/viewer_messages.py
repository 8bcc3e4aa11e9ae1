"""Every message one websocket viewer receives from a still (or moving) console, by source.

``python benchmarks/viewer_messages.py [--robot soft-arm|extensible] [--seconds 20] [--move]``

Builds the whole console in this process as ``benchmarks/bench_viewers.py`` does (``serve.build``
with the emulator, every panel, lab mode; the soft arm armed and holding still on its control
process, the extensible arm at a bent pose with 100 Hz "motion capture" noise), connects one raw
websocket viewer (``tests/ws_client.py``) and prints, for each source (message type and the panel
widget or scene node it updates), how many messages arrived per second and their msgpack size:
what a still console costs, accounted line by line.
"""

from __future__ import annotations

import argparse
import collections
import sys
import threading
import time
from pathlib import Path
from typing import Any

import msgspec

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))
sys.path.insert(0, str(REPO / "tests"))


def widget_names(app: Any) -> dict[str, str]:
    """uuid -> "Panel.attribute" for every GUI handle an app's panels (and header) hold."""
    names: dict[str, str] = {}

    def visit(owner: str, obj: Any, depth: int = 0) -> None:
        for attr, value in list(vars(obj).items()):
            impl = getattr(value, "_impl", None)
            uuid = getattr(impl, "uuid", None)
            if isinstance(uuid, str):
                names.setdefault(uuid, f"{owner}.{attr}")
            elif depth < 1 and hasattr(value, "__dict__") and not isinstance(value, type):
                if type(value).__module__.startswith("console"):
                    visit(f"{owner}.{attr}", value, depth + 1)

    for panel in app.panels:
        visit(type(panel).__name__, panel)
    visit("app", app)
    visit("header", app.header)
    return names


def binary_bytes(value: Any, lengths: list[int]) -> int:
    """Bytes of the binary buffers (numpy arrays sent raw after the msgpack) a message holds."""
    if isinstance(value, dict):
        if "__binary_index" in value:
            return int(lengths[value["__binary_index"]])
        return sum(binary_bytes(v, lengths) for v in value.values())
    if isinstance(value, (list, tuple)):
        return sum(binary_bytes(v, lengths) for v in value)
    return 0


def counting_client(server: Any) -> Any:
    """A ``ws_client.RawClient`` that keeps each message's size: msgpack plus binary buffers,
    and its share of the compressed websocket frame it came in."""
    from ws_client import RawClient, decode_payload

    class CountingClient(RawClient):
        def __init__(self, server: Any) -> None:
            self.sized: list[tuple[dict[str, Any], int, float]] = []
            self.wire = 0
            super().__init__(server)  # (starts the receive thread)

        def on_frame(self, frame: bytes) -> None:
            inner = decode_payload(frame)
            lengths = list(inner["binaryBufferLengths"])
            messages = list(inner["messages"])
            raw = [len(msgspec.msgpack.encode(m)) + binary_bytes(m, lengths) for m in messages]
            with self._lock:
                self.frames += 1
                self.wire += len(frame)
                self.messages.extend(messages)
                total = max(sum(raw), 1)
                self.sized.extend((m, r, len(frame) * r / total)
                                  for m, r in zip(messages, raw))

        def clear(self) -> None:
            with self._lock:
                self.messages.clear()
                self.sized.clear()
                self.wire = 0

    return CountingClient(server)


def source(m: dict[str, Any], names: dict[str, str]) -> str:
    kind = m.get("type", "?")
    if "uuid" in m:
        keys = ",".join(sorted(m.get("updates", {}))) if "updates" in m else ""
        return f"{kind} {names.get(m['uuid'], m['uuid'][:8])} [{keys}]"
    if "name" in m:
        name = str(m["name"])
        keys = ",".join(sorted(m.get("updates", {}))) if "updates" in m else ""
        return f"{kind} {name} [{keys}]" if keys else f"{kind} {name}"
    return kind


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robot", default="soft-arm")
    p.add_argument("--seconds", type=float, default=20.0)
    p.add_argument("--warmup", type=float, default=3.0)
    p.add_argument("--move", action="store_true", help="trials / demo motion instead of still")
    p.add_argument("--data-dir", default="/tmp/viewer_messages")
    p.add_argument("--texts", action="store_true",
                   help="also print every text (markdown, HTML) a viewer was sent, by source")
    p.add_argument("--band", choices=("default", "still-only"), default="default",
                   help="the arm view's dead band: as shipped, or without its moving band")
    a = p.parse_args()

    import bench_viewers as bv
    from core.robots import load
    from load_trials import start_trials

    serve = bv._serve_module()
    robot = load(a.robot)
    args = serve.parse_args(["--robot", a.robot, "--port", "0", "--lab", "--no-token",
                             "--data-dir", a.data_dir, "--rt-cpu", "none"])
    server, app, _ = serve.build(args, robot, "viewer messages")
    if a.band == "still-only":
        import dataclasses
        app.view.dead_band = dataclasses.replace(app.view.dead_band, moving_steadiness=2.0)
    app.start()
    stop = threading.Event()
    try:
        planner = next((pn for pn in app.panels if hasattr(pn, "reach_note")), None)
        t0 = time.monotonic()
        while planner is not None and time.monotonic() - t0 < 120.0:
            if "computing" not in str(planner.reach_note.content):
                break
            time.sleep(0.2)
        soft = app.services.soft_control
        q0 = bv.still_pose(app.model)
        if soft is not None:
            soft.arm().result(60)
            if a.move:
                start_trials(app, robot, stop)
        else:
            bv.mocap_only(app)
            app.store.request(q0, "bench")
            bv.start_mocap(app, q0, stop, moving=a.move)
        client = counting_client(server)
        time.sleep(a.warmup + (5.0 if a.move and soft is not None else 0.0))
        client.clear()
        frames0, sent0 = client.frames, app.view.frames_sent
        time.sleep(a.seconds)
        with client._lock:
            sized = list(client.sized)
            frames, wire = client.frames - frames0, client.wire
        sent = app.view.frames_sent - sent0
        names = widget_names(app)
        count: collections.Counter[str] = collections.Counter()
        size: collections.Counter[str] = collections.Counter()
        share: collections.Counter[str] = collections.Counter()
        for m, raw, part in sized:
            key = source(m, names)
            count[key] += 1
            size[key] += raw
            share[key] += part
        print(f"{a.robot} {'moving' if a.move else 'still'}: {len(sized) / a.seconds:.1f} "
              f"msg/s in {frames / a.seconds:.1f} websocket frames/s, "
              f"{wire / a.seconds / 1e3:.2f} KB/s on the wire; arm frames sent "
              f"{sent / a.seconds:.1f}/s")
        print(f"{'msg/s':>7s} {'raw B/s':>8s} {'wire B/s':>8s}  source (raw: msgpack + arrays; "
              "wire: its share of the compressed frames)")
        for key, n in sorted(count.items(), key=lambda kv: -share[kv[0]]):
            print(f"{n / a.seconds:7.2f} {size[key] / a.seconds:8.0f} "
                  f"{share[key] / a.seconds:8.0f}  {key}")
        if a.texts:  # what changed in them, to see why a still console re-sent a text
            for m, _, _ in sized:
                for prop, value in m.get("updates", {}).items():
                    if prop in ("_markdown", "content") and isinstance(value, str):
                        print(f"  {source(m, names)}: {value}")
    finally:
        stop.set()
        app.stop()
        app.services.close()
        server.stop()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
