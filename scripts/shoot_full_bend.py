"""Screenshots of both arms at full bend, skinned (drawn by pose) beside the old vertex mesh.

``python scripts/shoot_full_bend.py [--out artifacts/viewers]``

Issue 15's "done when": the arm drawn by pose must look as good as the vertex mesh it replaced.
One viser scene per case holds the same configuration twice, the skinned drawing (left, or in
front) and the vertex drawing (right, or behind) under two offset roots; headless Chromium
(/usr/bin/chromium, the browser tests' flags) shoots it from above and from an angle:

* soft arm, |kappa| = 16.7 1/m on every segment (a curl) and with alternating signs (where the
  curvature flips, the skin rounds the corner: the most it differs from the vertex mesh);
* extensible arm at full rack bend (each segment bent as far as its racks allow, one an S).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))
sys.path.insert(0, str(REPO / "tests" / "browser"))


def extensible_full_bend(model) -> np.ndarray:  # noqa: ANN001 - a ExtensibleModel
    """Each segment bent as far as its racks and its bend limit allow: the first along +x, the
    second along -x (an S), at mid extension."""
    r = model.robot
    q = np.zeros(model.shape)
    q[:, 2] = 0.5 * (r.rack_min + r.rack_max) - r.L0
    for i in range(len(q)):
        lo, hi = model.feasible_interval(q, i, 0)
        blo, bhi = model.bend_interval(q, i, 0)  # the bend limit theta_max
        q[i, 0] = min(hi, bhi) if i % 2 == 0 else max(lo, blo)
    return q


def shoot(robot_name: str, q: np.ndarray, offset: tuple[float, float, float],
          cameras: dict[str, tuple[float, float, float]], out: Path,
          stem: str, browser) -> list[Path]:  # noqa: ANN001 - a Playwright browser
    import viser

    from console.scene.arm_view_factory import make_arm_view
    from console.core.model import model_for
    from core.robots import load

    robot = load(robot_name)
    model = model_for(robot)
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    shots: list[Path] = []
    try:
        scene = server.scene
        scene.configure_environment_map(None)
        scene.configure_default_lights(enabled=True, cast_shadow=False)
        scene.add_light_hemisphere("/lights", sky_color=(255, 255, 255),
                                   ground_color=(120, 120, 120), intensity=1.3)
        scene.world_axes.visible = False
        scene.add_grid("/grid", width=2.0, height=2.0, cell_size=0.05, section_size=0.25)
        scene.add_frame("/skinned", show_axes=False)
        scene.add_frame("/vertices", show_axes=False, position=offset)
        for method in ("skinned", "vertices"):
            view = make_arm_view(scene, model, root=f"/{method}", method=method, dead_band=None)
            view.update(q)
            scene.add_label(f"/{method}/label", "skinned (new)" if method == "skinned" else
                            "vertices (old)", position=(0.0, -0.06, 0.0))
        body = view.geometry(q)
        pts = np.asarray(body["body"] if "body" in body else body["backbone"], dtype=float)
        pts = np.concatenate([pts, pts + np.asarray(offset)])
        centre = 0.5 * (pts.min(0) + pts.max(0))
        extent = float(np.max(pts.max(0) - pts.min(0)))
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        page.goto(f"http://127.0.0.1:{server.get_port()}/")
        deadline = time.monotonic() + 240.0
        while not server.get_clients():
            if time.monotonic() > deadline:
                raise RuntimeError("the browser never connected")
            time.sleep(0.1)
        client = next(iter(server.get_clients().values()))
        from browser_tabs import close_notices
        close_notices(page)  # the browser's "Software WebGL" notice (in a corner if it stays)
        for name, direction in cameras.items():
            d = np.asarray(direction, dtype=float)
            client.camera.up_direction = (0.0, 0.0, 1.0)
            client.camera.position = tuple(centre + 1.6 * extent * d / np.linalg.norm(d))
            client.camera.look_at = tuple(centre)
            time.sleep(8.0)  # software rendering (on a loaded machine)
            path = out / f"{stem}_{name}.png"
            page.screenshot(path=str(path))
            shots.append(path)
        page.close()
    finally:
        server.stop()
    return shots


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default=str(REPO / "artifacts" / "viewers"))
    a = p.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)

    from playwright.sync_api import sync_playwright

    from conftest import CHROMIUM, CHROMIUM_ARGS
    from console.core.model import model_for
    from core.robots import load

    k = load("soft-arm").kappa_max
    soft_cases = {"soft_curl": np.full(6, k),
                  "soft_alternating": k * np.array([1.0, -1.0, 1.0, -1.0, 1.0, -1.0])}
    soft_cameras = {"top": (0.0, -0.01, 1.0), "angle": (0.0, -0.7, 0.6)}
    ext_q = extensible_full_bend(model_for(load("extensible")))
    ext_cameras = {"front": (0.0, -1.0, 0.1), "angle": (0.5, -0.8, 0.5)}
    shots: list[Path] = []
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(CHROMIUM), headless=True,
                                     args=CHROMIUM_ARGS)
        try:
            for stem, q in soft_cases.items():
                shots += shoot("soft-arm", q, (0.25, 0.0, 0.0), soft_cameras, out, stem, browser)
            shots += shoot("extensible", ext_q, (0.3, 0.0, 0.0), ext_cameras, out,
                           "extensible_full_bend", browser)
        finally:
            browser.close()
    for s in shots:
        print(s)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
