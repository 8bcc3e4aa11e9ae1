"""The one reader every robot-file section goes through, so each error names file, section and key.

A :class:`Section` wraps one TOML table. Each typed read (:meth:`Section.num`,
:meth:`Section.integer`, ...) records the key as known, checks type, finiteness and bounds, and
raises :class:`RobotFileError` as ``<file>: <section>.<key>: <what is wrong>``, e.g.
``soft-arm.toml: controller.kp: must be >= 0, got -1``. :meth:`Section.finish` then refuses any
key that was not read, listing the known ones::

    soft-arm.toml: [planner]: unknown key 'weight'; known keys: base_keepout, clearance_margin, ...

Also home of the ``tomllib`` import with its Python 3.10 fallback (``tomli``).
"""

from __future__ import annotations

import difflib
import math
from typing import Any, Mapping, Sequence

try:  # Python 3.11+
    import tomllib
except ModuleNotFoundError:  # Python 3.10: the same parser as a package (pyproject dependency)
    import tomli as tomllib  # type: ignore[no-redef]

__all__ = ["RobotFileError", "Section", "check_number", "tomllib"]

_REQUIRED: Any = object()


class RobotFileError(ValueError):
    """A robot description file is missing a field or has a bad value."""


def _is_number(value: Any) -> bool:
    return (not isinstance(value, bool) and isinstance(value, (int, float))
            and math.isfinite(value))


def check_number(value: Any, field: str, *, lo: float | None = None, hi: float | None = None,
                 strict_lo: bool = False) -> float:
    """``value`` as a finite float within bounds, or :class:`RobotFileError` naming ``field``."""
    if not _is_number(value):
        raise RobotFileError(f"{field}: must be a finite number, got {value!r}")
    value = float(value)
    if lo is not None and (value <= lo if strict_lo else value < lo):
        raise RobotFileError(f"{field}: must be {'>' if strict_lo else '>='} {lo:g}, got {value:g}")
    if hi is not None and value > hi:
        raise RobotFileError(f"{field}: must be <= {hi:g}, got {value:g}")
    return value


class Section:
    """One table of a robot file being read; remembers which keys were read.

    Args:
        table: The parsed TOML table.
        file: File label used in messages (``soft-arm.toml`` or the path given).
        name: Dotted section name (``"controller"``, ``"sim.mocap"``; ``""`` for the top level).
    """

    def __init__(self, table: Mapping[str, Any], file: str, name: str = ""):
        self.table, self.file, self.name = table, file, name
        self.known: list[str] = []

    # ---- messages ----------------------------------------------------------------------------
    def field(self, key: str) -> str:
        """Dotted field name, e.g. ``controller.kp``."""
        return f"{self.name}.{key}" if self.name else key

    def error(self, key: str, message: str) -> RobotFileError:
        """A :class:`RobotFileError` naming the file and ``section.key``."""
        return RobotFileError(f"{self.file}: {self.field(key)}: {message}")

    def value(self, key: str, default: Any = _REQUIRED) -> Any:
        """The raw value of ``key`` (recorded as known); for shapes the typed reads do not cover."""
        if key not in self.known:
            self.known.append(key)
        if key in self.table:
            return self.table[key]
        if default is _REQUIRED:
            where = f"[{self.name}]" if self.name else "the top level"
            others = {str(k).lower(): k for k in self.table if k not in self.known}
            near = difflib.get_close_matches(key.lower(), list(others), n=1, cutoff=0.6)
            hint = f"; the table has {others[near[0]]!r}: a misspelling?" if near else ""
            raise self.error(key, f"missing (a required key of {where}){hint}")
        return default

    # ---- typed reads -------------------------------------------------------------------------
    def num(self, key: str, *, lo: float | None = None, hi: float | None = None,
            strict_lo: bool = False, default: Any = _REQUIRED) -> float:
        """A finite number within ``[lo, hi]`` (``(lo, hi]`` with ``strict_lo``)."""
        value = self.value(key, default)
        try:
            return check_number(value, self.field(key), lo=lo, hi=hi, strict_lo=strict_lo)
        except RobotFileError as exc:
            raise RobotFileError(f"{self.file}: {exc}") from None

    def integer(self, key: str, *, lo: int, hi: int, default: Any = _REQUIRED) -> int:
        """An integer within ``[lo, hi]`` (bounds keep a typo from hanging start-up)."""
        value = self.value(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
            raise self.error(key, f"must be an integer in [{lo}, {hi}], got {value!r}")
        return value

    def flag(self, key: str, default: Any = _REQUIRED) -> bool:
        """``true`` or ``false``."""
        value = self.value(key, default)
        if not isinstance(value, bool):
            raise self.error(key, f"must be true or false, got {value!r}")
        return value

    def choice(self, key: str, choices: Sequence[str], default: Any = _REQUIRED) -> str:
        """One of ``choices``."""
        value = self.value(key, default)
        if value not in choices:
            raise self.error(key, f"must be one of {', '.join(repr(c) for c in choices)}, "
                                  f"got {value!r}")
        return value

    def text(self, key: str, default: Any = _REQUIRED) -> str:
        """A non-empty string."""
        value = self.value(key, default)
        if not isinstance(value, str) or not value.strip():
            raise self.error(key, f"must be a non-empty string, got {value!r}")
        return value

    def numbers(self, key: str, n: int, *, per: str = "segment",
                count_field: str = "segments.count", lo: float | None = None, hi: float | None = None, strict_lo: bool = False,
                broadcast: bool = True, default: Any = _REQUIRED) -> tuple[float, ...]:
        """``n`` numbers in bounds: a list of exactly ``n`` or (``broadcast``) one number for all.

        A list of the wrong length is refused naming ``count_field``, so a robot file whose
        segment count changed says which per-segment list still has the old length.
        """
        value = self.value(key, default)
        if broadcast and _is_number(value):
            value = [value] * n
        if not isinstance(value, list):
            shape = "a number or a list" if broadcast else "a list"
            raise self.error(key, f"must be {shape} of {n} numbers (one per {per}), got {value!r}")
        if len(value) != n:
            raise self.error(key, f"must have {n} entries, one per {per} ({count_field} = {n}), "
                                  f"got {len(value)}: {value!r}")
        out = []
        for i, v in enumerate(value):
            try:
                out.append(check_number(v, f"{self.field(key)}[{i}]", lo=lo, hi=hi,
                                        strict_lo=strict_lo))
            except RobotFileError as exc:
                raise RobotFileError(f"{self.file}: {exc}") from None
        return tuple(out)

    def interval(self, key: str, *, lo: float = 0.0, hi: float = 3600.0) -> tuple[float, float]:
        """``[a, b]`` with ``lo <= a <= b <= hi``, both finite."""
        value = self.value(key, _REQUIRED)
        if (not isinstance(value, list) or len(value) != 2 or not all(map(_is_number, value))
                or not lo <= value[0] <= value[1] <= hi):
            raise self.error(key, f"must be [a, b] with {lo:g} <= a <= b <= {hi:g}, got {value!r}")
        return float(value[0]), float(value[1])

    def sub(self, key: str, *, required: bool = True) -> "Section":
        """The sub-table ``key`` (``[name.key]``); an absent optional one reads as empty."""
        if required and key not in self.table:
            self.known.append(key)
            raise RobotFileError(f"{self.file}: [{self.field(key)}]: missing section")
        value = self.value(key, {})
        if not isinstance(value, Mapping):
            name = self.field(key)
            raise RobotFileError(f"{self.file}: [{name}]: must be a table, got {value!r}")
        return Section(value, self.file, self.field(key))

    def finish(self) -> None:
        """Refuse every key that no read asked for, listing the known ones."""
        unknown = [k for k in self.table if k not in self.known]
        if unknown:
            where = f"[{self.name}]" if self.name else "top level"
            keys = ", ".join(repr(k) for k in unknown)
            raise RobotFileError(
                f"{self.file}: {where}: unknown key{'s' if len(unknown) > 1 else ''} {keys}; "
                f"known keys: {', '.join(sorted(self.known))}")
