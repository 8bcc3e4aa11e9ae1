"""A design study's results in the console: which study is open and which variant is shown.

``python -m core.study --out DIR`` (issue 30) writes one row per robot-file variant into
``DIR/results.parquet`` and ``DIR/results.csv`` (SI units in the column names) and each
variant's robot file as ``DIR/<variant>.toml``. The Experiments tab's *Design study* panel opens
such a folder and shows a variant's arm beside the console's own; this module is the headless
state behind it (no viser, no app), one :class:`DesignStudies` per console
(``ConsoleApp.design_study``): the panel and the 3D layer
(:class:`console.scene.study_ghost.StudyGhostView`) render it and call it, and keep nothing.

Files: a browser may only make the console read inside its data folder (``--data-dir``,
:mod:`console.core.datadir`), so a study folder is found or typed relative to it (an absolute
path is accepted when it lies inside it) and refused with the reason otherwise, before any file
is read. A refused request changes nothing: the study open before stays open.
"""

from __future__ import annotations

import csv
import dataclasses
import math
import os
import threading
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from core.robot_schema import RobotFileError
from core.robots import Robot, load

RESULTS = ("results.parquet", "results.csv")  # what core.study writes, read in this order
MAX_DEPTH = 3            # how deep below the data folder study folders are looked for
MAX_FOLDERS = 2000       # folders looked into at most when listing studies
MAX_BYTES = 16 * 2**20   # largest results file read (a row per variant: far more than a study)
MAX_ROWS = 10_000        # most variants a study may have
NOT_MEASURED = ("variant", "error")  # columns core.study writes that are no metric


class StudyError(ValueError):
    """A study folder or variant was refused; the message says why, for the person asking."""


@dataclasses.dataclass(frozen=True)
class StudyResults:
    """One study as read from its folder.

    Attributes:
        folder: The study folder (resolved).
        label: The folder relative to the data folder (what the panel shows).
        source: The file the rows came from (``results.parquet`` or ``results.csv``).
        rows: One mapping per variant, in study order; a value the file leaves empty (a failed
            variant's metrics) is absent, as in core.study's own rows.
        columns: Every column, in file order.
        keys: The varied robot-file keys (``section.key`` columns), in file order.
        metrics: The numeric columns that are neither a varied key nor ``variant``.
        best: The best variant per metric, by core.study's own rule (:func:`core.study.best`).
    """

    folder: Path
    label: str
    source: str
    rows: tuple[Mapping[str, Any], ...]
    columns: tuple[str, ...]
    keys: tuple[str, ...]
    metrics: tuple[str, ...]
    best: Mapping[str, str]

    @property
    def variants(self) -> tuple[str, ...]:
        """The variants' names, in study order."""
        return tuple(str(r["variant"]) for r in self.rows)

    def column(self, name: str) -> npt.NDArray[np.float64]:
        """Column ``name`` as floats (SI, as in the file); NaN where a row has no number."""
        if name not in self.columns:
            raise KeyError(f"no column {name!r} in {self.label}")
        return np.array([_number(r.get(name)) for r in self.rows], dtype=float)

    def robot_file(self, variant: str) -> Path:
        """The variant's robot file ``<variant>.toml`` in the study folder.

        Raises:
            StudyError: no such variant, its file is missing or lies outside the folder.
        """
        if variant not in self.variants:
            raise StudyError(f"{self.label} has no variant {variant!r}")
        path = (self.folder / f"{variant}.toml").resolve()
        if path.parent != self.folder:
            raise StudyError(f"variant {variant!r}: its robot file is not in {self.label}")
        if not path.is_file():
            raise StudyError(f"{self.label}: no robot file {variant}.toml beside the results "
                             "(core.study writes one per variant)")
        return path


@dataclasses.dataclass(frozen=True)
class ShownVariant:
    """A variant's arm drawn beside the console's own.

    Attributes:
        study: The study's label.
        name: The variant's name.
        robot: Its robot file, loaded and checked.
    """

    study: str
    name: str
    robot: Robot


def _number(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return math.nan
    return float(value)


def _cell(text: str) -> Any:
    """A CSV cell as core.study wrote it: an int, a float, text, or absent (empty)."""
    if text == "":
        return None
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


def read_rows(folder: Path) -> tuple[str, list[dict[str, Any]], list[str]]:
    """(file name, rows, columns) of a study folder's results, Parquet first, then CSV.

    Raises:
        StudyError: neither file is there, one is too big or cannot be read.
    """
    for name in RESULTS:
        path = folder / name
        if not path.is_file():
            continue
        if path.stat().st_size > MAX_BYTES:
            raise StudyError(f"{name} is larger than {MAX_BYTES // 2**20} MB: not a design "
                             "study's results")
        try:
            if name.endswith(".parquet"):
                import pyarrow.parquet as pq

                table = pq.read_table(path)
                columns = list(table.column_names)
                raw = table.to_pylist()
            else:
                with open(path, newline="", encoding="utf-8") as fh:
                    reader = csv.DictReader(fh)
                    columns = list(reader.fieldnames or [])
                    raw = [{k: _cell(v or "") for k, v in row.items() if k is not None}
                           for row in reader]
        except Exception as exc:  # noqa: BLE001 - any unreadable file: say which and why
            raise StudyError(f"cannot read {name}: {type(exc).__name__}: {exc}") from None
        # an empty cell (CSV) or null (Parquet) is a value the row does not have
        rows = [{k: v for k, v in r.items() if v is not None and v != ""} for r in raw]
        return name, rows, columns
    done = folder / "variants"
    finished = len(list(done.glob("*.json"))) if done.is_dir() else 0
    more = (f" ({finished} variants finished: the study has not ended; run its command again "
            "to finish it)") if finished else ""
    raise StudyError(f"no {' or '.join(RESULTS)} in it{more}")


def study_results(folder: Path, label: str) -> StudyResults:
    """Read and check the study in ``folder`` (already resolved and allowed).

    Raises:
        StudyError: not a design study's results (the message says what is wrong).
    """
    from core.study import best

    source, rows, columns = read_rows(folder)
    if "variant" not in columns:
        raise StudyError(f"{source} has no 'variant' column: not a design study's results")
    if not rows:
        raise StudyError(f"{source} has no rows")
    if len(rows) > MAX_ROWS:
        raise StudyError(f"{source} has {len(rows)} rows; at most {MAX_ROWS} are shown")
    names = [r.get("variant") for r in rows]
    if any(not isinstance(n, str) or not n for n in names):
        raise StudyError(f"{source}: a row has no variant name")
    if len(set(names)) != len(names):
        raise StudyError(f"{source}: variant names repeat")
    keys = tuple(c for c in columns if "." in c and c not in NOT_MEASURED)
    metrics = tuple(
        c for c in columns if c not in NOT_MEASURED and c not in keys
        and any(c in r for r in rows)
        and all(isinstance(r[c], (int, float)) and not isinstance(r[c], bool)
                for r in rows if c in r))
    return StudyResults(folder, label, source, tuple(rows), tuple(columns), keys, metrics,
                        dict(best(rows)))


class DesignStudies:
    """The console's open design study and the variant shown beside the arm (thread-safe).

    Args:
        root: The console's data folder (``--data-dir``): the only folder studies are read from.
    """

    def __init__(self, root: Path | str) -> None:
        self._root = Path(root)
        self._lock = threading.Lock()
        self._results: StudyResults | None = None
        self._shown: ShownVariant | None = None
        self._listeners: list[Callable[[], None]] = []

    @property
    def root(self) -> Path:
        """The data folder, resolved."""
        return self._root.expanduser().resolve()

    @property
    def results(self) -> StudyResults | None:
        """The open study (None before one is opened)."""
        with self._lock:
            return self._results

    @property
    def shown(self) -> ShownVariant | None:
        """The variant drawn beside the arm (None: none)."""
        with self._lock:
            return self._shown

    def add_listener(self, fn: Callable[[], None]) -> None:
        """Call ``fn()`` after every change (a study opened, a variant shown or hidden), on the
        caller's thread, outside the lock."""
        with self._lock:
            self._listeners.append(fn)

    def studies(self) -> list[str]:
        """Study folders under the data folder (a ``results.parquet`` or ``results.csv`` in
        them), relative to it, sorted; at most :data:`MAX_DEPTH` deep, symlinks not followed."""
        root = self.root
        found: list[str] = []
        todo: list[tuple[Path, int]] = [(root, 0)]
        seen = 0
        while todo and seen < MAX_FOLDERS:
            folder, depth = todo.pop()
            seen += 1
            try:
                entries = list(os.scandir(folder))
            except OSError:
                continue
            names = {e.name for e in entries if e.is_file(follow_symlinks=False)}
            if folder != root and names & set(RESULTS):
                found.append(folder.relative_to(root).as_posix())
            if depth < MAX_DEPTH:
                todo += [(Path(e.path), depth + 1) for e in entries
                         if e.is_dir(follow_symlinks=False) and not e.name.startswith(".")]
        return sorted(found)

    def folder(self, text: object) -> tuple[Path, str]:
        """(resolved folder, label) of a typed or picked study folder.

        Raises:
            StudyError: not text, empty, outside the data folder, missing or not a folder.
        """
        if not isinstance(text, str) or not text.strip():
            raise StudyError("type a study folder (relative to the console's data folder)")
        if "\x00" in text:
            raise StudyError("a folder name cannot hold a NUL character")
        root = self.root
        given = Path(text.strip()).expanduser()
        folder = (given if given.is_absolute() else root / given).resolve()
        if not folder.is_relative_to(root):
            raise StudyError(f"{text.strip()!r} is outside the console's data folder ({root}): "
                             "studies are opened from there only (core.study --out "
                             f"{root / 'studies' / 'NAME'})")
        if not folder.is_dir():
            raise StudyError(f"{text.strip()!r}: no such folder in {root}")
        label = folder.relative_to(root).as_posix()
        return folder, label if label != "." else "(the data folder)"

    def open(self, text: object) -> StudyResults:
        """Open the study in folder ``text`` (relative to the data folder); a variant shown
        from another study is hidden.

        Raises:
            StudyError: the folder or its results were refused (nothing changed).
        """
        folder, label = self.folder(text)
        try:
            results = study_results(folder, label)
        except StudyError as exc:
            raise StudyError(f"{label}: {exc}") from None
        with self._lock:
            self._results = results
            if self._shown is not None and self._shown.study != label:
                self._shown = None
        self._tell()
        return results

    def show(self, variant: object) -> ShownVariant:
        """Draw ``variant`` of the open study beside the arm (its robot file, loaded and
        checked).

        Raises:
            StudyError: no study open, no such variant or a robot file the schema refuses
                (nothing changed).
        """
        results = self.results
        if results is None:
            raise StudyError("open a study first")
        if not isinstance(variant, str):
            raise StudyError("pick a variant")
        path = results.robot_file(variant)
        try:
            robot = load(path)
        except RobotFileError as exc:
            raise StudyError(f"{variant}: {exc}") from None
        shown = ShownVariant(results.label, variant, robot)
        with self._lock:
            self._shown = shown
        self._tell()
        return shown

    def hide(self) -> None:
        """Take the variant's arm out of the 3D view (nothing shown: nothing changes)."""
        with self._lock:
            if self._shown is None:
                return
            self._shown = None
        self._tell()

    def _tell(self) -> None:
        with self._lock:
            listeners = list(self._listeners)
        for fn in listeners:
            fn()

