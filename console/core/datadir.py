"""The console's data folder, the only place a browser can make the server read or write files.

Every file name that arrives from the GUI (a recording to load, a name to save under) goes
through :meth:`DataDir.path`: it must be a plain base name of letters, digits, ``-``, ``_`` and
``.`` (no folders, no leading dot, no ``..``), end with the expected suffix, and its resolved
path (symlinks followed) must stay inside the data folder. Anything else raises
:class:`BadFileName` with a message for the user, before any file is touched.
"""

from __future__ import annotations

import re
import time
from pathlib import Path

NAME_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,99}")
STEM_RE = re.compile(r"[^A-Za-z0-9._-]+")


class BadFileName(ValueError):
    """A file name from the GUI was refused; the message says why."""


class DataDir:
    """Files under one root folder, by kind (sub-folder) and sanitised name.

    Args:
        root: The data folder (created if missing), e.g. ``./runs``.
    """

    KINDS = ("recordings", "exports")

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root).expanduser().resolve()
        for kind in self.KINDS:
            (self.root / kind).mkdir(parents=True, exist_ok=True)

    def folder(self, kind: str) -> Path:
        if kind not in self.KINDS:
            raise ValueError(f"unknown kind {kind!r}; expected one of {self.KINDS}")
        return self.root / kind

    def path(self, kind: str, name: object, suffix: str) -> Path:
        """The file ``name`` of ``kind`` (e.g. "recordings"), checked as the module says.

        Raises:
            BadFileName: the name is not a plain base name ending in ``suffix`` inside the folder.
        """
        if not isinstance(name, str):
            raise BadFileName("file name must be text")
        if name != name.strip() or "/" in name or "\\" in name or "\x00" in name:
            raise BadFileName(f"{name!r} is not a plain file name (no folders, no spaces "
                              "around it)")
        if ".." in name or not NAME_RE.fullmatch(name):
            raise BadFileName(f"{name!r}: use letters, digits, '-', '_' and '.' only, not "
                              "starting with '.', at most 100 characters")
        if not name.endswith(suffix):
            raise BadFileName(f"{name!r} must end with {suffix}")
        folder = self.folder(kind)
        path = (folder / name).resolve()
        if path.parent != folder.resolve() or not path.is_relative_to(self.root):
            raise BadFileName(f"{name!r} points outside the console's data folder")
        return path

    def new_name(self, kind: str, stem: object, suffix: str) -> str:
        """A fresh (not yet existing) file name from free text ``stem`` and a time stamp."""
        text = STEM_RE.sub("-", str(stem or "")).strip("-._")[:40]
        base = f"{text}-{time.strftime('%Y%m%d-%H%M%S')}" if text else time.strftime(
            "%Y%m%d-%H%M%S")
        name, n = f"{base}{suffix}", 1
        while (self.folder(kind) / name).exists():
            n += 1
            name = f"{base}-{n}{suffix}"
        return name

    def list(self, kind: str, suffix: str) -> list[str]:
        """Names of the regular files of ``kind`` ending in ``suffix``, newest first."""
        folder = self.folder(kind)
        files = [p for p in folder.iterdir()
                 if p.is_file() and not p.is_symlink() and p.name.endswith(suffix)
                 and NAME_RE.fullmatch(p.name)]
        files.sort(key=lambda p: p.stat().st_mtime, reverse=True)
        return [p.name for p in files]
