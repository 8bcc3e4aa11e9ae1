"""The console's reachability map, ready at once when the robot file has not changed.

A map (:mod:`core.planning.reachability`) takes tens of seconds of CPU, so it is cached on disk
under a key made of the robot file's contents (SHA-256), the object radius, the grid (table
extent, cell size, coarse-to-fine levels) and the algorithm's version
(:data:`core.planning.reachability.ALGORITHM_VERSION`): a changed robot file or planner gets a
new key, never a stale map. :class:`ReachCache` looks in the console's data folder
(``<data dir>/cache``, where it writes) and then in the maps shipped with the repository
(``data/reach_cache``); a corrupt or mismatched file is logged and ignored. On a miss
:func:`start_reach_map` runs ``python -m core.planning.reachability --progress`` in a
low-priority child process (no GIL or GUI-thread contention), reports its progress lines and
hands back a :class:`ReachOutcome` (the map, how long it took or that it came from the cache).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import os
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from core.planning.reachability import (ALGORITHM_VERSION, DEFAULT_LEVELS, ReachMap, from_json,
                                        grid_axis, to_json)
from hw_bridge.parent_watch import death_signal_preexec

log = logging.getLogger(__name__)
REPO = Path(__file__).resolve().parents[2]
SHIPPED_CACHE = REPO / "data" / "reach_cache"
REACH_STEP = 0.02


@dataclasses.dataclass(frozen=True)
class ReachRequest:
    """One map: robot file, object radius, grid.

    Attributes:
        robot_file: The robot's TOML file (its contents are part of the key).
        radius: Object radius (m).
        x_range, y_range: Grid extent (m), normally the table rectangle.
        step: Largest cell size (m).
        levels: Coarse-to-fine levels of :func:`core.planning.reachability.reachability_map`.
    """

    robot_file: Path
    radius: float
    x_range: tuple[float, float]
    y_range: tuple[float, float]
    step: float = REACH_STEP
    levels: int = DEFAULT_LEVELS

    def key(self) -> str:
        """Hex digest of everything the map depends on (robot file read now)."""
        robot_hash = hashlib.sha256(Path(self.robot_file).read_bytes()).hexdigest()
        parts = {"robot": robot_hash, "radius": repr(float(self.radius)),
                 "x": [repr(float(v)) for v in self.x_range],
                 "y": [repr(float(v)) for v in self.y_range], "step": repr(float(self.step)),
                 "levels": int(self.levels), "version": ALGORITHM_VERSION}
        return hashlib.sha256(json.dumps(parts, sort_keys=True).encode()).hexdigest()[:32]

    def command(self) -> list[str]:
        """The child process that computes the map (progress lines on stderr)."""
        return [sys.executable, "-m", "core.planning.reachability", "--robot",
                str(self.robot_file), "--radius", repr(float(self.radius)),
                "--x", *map(repr, map(float, self.x_range)),
                "--y", *map(repr, map(float, self.y_range)), "--step", repr(float(self.step)),
                "--levels", str(int(self.levels)), "--progress"]


@dataclasses.dataclass(frozen=True)
class ReachOutcome:
    """A finished map request: the map (or the error), its time and where it came from."""

    reach: ReachMap | None
    seconds: float
    from_cache: bool
    error: str | None = None

    def note(self) -> str:
        """"from cache" / "computed in 12.3 s" / "failed: ..." for the planner panel."""
        if self.error is not None:
            return f"failed: {self.error}"
        return "from cache" if self.from_cache else f"computed in {self.seconds:.1f} s"


class ReachCache:
    """Maps on disk, one JSON file per key; reads ``folders`` in order, writes the first."""

    def __init__(self, *folders: Path | str) -> None:
        self.folders = [Path(f) for f in folders]

    def file(self, key: str, folder: Path | None = None) -> Path:
        return (self.folders[0] if folder is None else folder) / f"reach-{key}.json"

    def load(self, request: ReachRequest) -> ReachMap | None:
        """The cached map of ``request``, or None (a bad file is logged and skipped)."""
        key = request.key()
        for folder in self.folders:
            path = self.file(key, folder)
            if not path.is_file():
                continue
            try:
                return _checked(json.loads(path.read_text()), key, request)
            except (OSError, ValueError, KeyError, TypeError) as exc:
                log.warning("ignoring reachability cache %s (%s); recomputing", path, exc)
        return None

    def save(self, request: ReachRequest, reach: ReachMap) -> Path | None:
        """Write ``reach`` for ``request`` (atomically); None if the folder is not writable."""
        path = self.file(request.key())
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(f".{os.getpid()}.tmp")
            tmp.write_text(json.dumps({"key": request.key(), "version": ALGORITHM_VERSION,
                                       "map": json.loads(to_json(reach))}))
            os.replace(tmp, path)
        except OSError as exc:
            log.warning("could not write reachability cache %s: %s", path, exc)
            return None
        return path


def _checked(data: dict, key: str, request: ReachRequest) -> ReachMap:
    """The map in a cache file's ``data`` if it is the map of ``request``; else ValueError."""
    if data.get("key") != key or data.get("version") != ALGORITHM_VERSION:
        raise ValueError("key or version does not match")
    reach = from_json(json.dumps(data["map"]))
    xs, ys = grid_axis(*request.x_range, request.step), grid_axis(*request.y_range, request.step)
    if (reach.status.shape != (len(ys), len(xs)) or not np.allclose(reach.xs, xs)
            or not np.allclose(reach.ys, ys) or abs(reach.radius - request.radius) > 1e-12
            or not np.isin(reach.status, (0, 1, 2)).all()):
        raise ValueError("grid, radius or status values do not match the request")
    return reach


_MEMORY: dict[str, ReachMap] = {}
_MEMORY_LOCK = threading.Lock()


def start_reach_map(request: ReachRequest, cache: ReachCache | None,
                    done: Callable[[ReachOutcome], None],
                    progress: Callable[[float], None] | None = None) -> None:
    """Hand ``done`` the map of ``request``: from memory or ``cache`` at once (in this thread),
    else from a low-priority child process (``progress(fraction)`` on each of its progress
    lines, ``done`` from a daemon thread that waits for it; the map is then cached)."""
    t0 = time.perf_counter()
    try:
        key = request.key()
    except OSError as exc:
        done(ReachOutcome(None, 0.0, False, f"cannot read the robot file ({exc})"))
        return
    with _MEMORY_LOCK:
        hit = _MEMORY.get(key)
    if hit is None and cache is not None:
        hit = cache.load(request)
    if hit is not None:
        with _MEMORY_LOCK:
            _MEMORY[key] = hit
        done(ReachOutcome(hit, time.perf_counter() - t0, True))
        return

    def wait() -> None:
        cmd = request.command() + ["--nice", "15", "--parent", str(os.getpid())]
        try:
            # (killed with this thread's process: see hw_bridge.parent_watch)
            proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                    text=True, cwd=str(REPO), preexec_fn=death_signal_preexec())
            out: list[str] = []
            reader = threading.Thread(target=lambda: out.append(proc.stdout.read()),
                                      name="reachability-out", daemon=True)
            reader.start()
            other: list[str] = []
            for line in proc.stderr:
                if line.startswith("progress "):
                    if progress is not None:
                        progress(float(line.split()[1]))
                else:
                    other.append(line)
            reader.join()
            if proc.wait() != 0:
                raise RuntimeError(f"exit {proc.returncode}: {''.join(other[-5:]).strip()}")
            reach = from_json(out[0])
        except (subprocess.SubprocessError, OSError, ValueError, KeyError, RuntimeError) as exc:
            done(ReachOutcome(None, time.perf_counter() - t0, False,
                              f"reachability map failed: {exc}"))
            return
        with _MEMORY_LOCK:
            _MEMORY[key] = reach
        if cache is not None:
            cache.save(request, reach)
        done(ReachOutcome(reach, time.perf_counter() - t0, False))

    threading.Thread(target=wait, name="reachability-wait", daemon=True).start()
