"""Progress bars for the long CLIs (trials, capture, convert): on a terminal only, no threads.

:func:`progress_bar` is a ``tqdm`` bar on stderr when stderr is a terminal and a no-op object
otherwise, so piped or redirected output carries nothing extra. tqdm's monitor thread is off
(``monitor_interval = 0``): ``core`` stays free of threads.
"""

from __future__ import annotations

import sys
from typing import Any, TextIO

from tqdm import tqdm


class _Bar(tqdm):  # type: ignore[misc]
    monitor_interval = 0  # no TMonitor thread


class NoBar:
    """What :func:`progress_bar` returns when nothing is shown: accepts the same calls."""

    n = 0

    def update(self, n: float = 1) -> None:
        self.n += n

    def set_postfix_str(self, text: str = "", refresh: bool = True) -> None:
        pass

    def close(self) -> None:
        pass

    def __enter__(self) -> NoBar:
        return self

    def __exit__(self, *exc: object) -> None:
        pass


def progress_bar(total: float | None, desc: str, unit: str = "it", *,
                 stream: TextIO | None = None, force: bool | None = None, **kw: Any) -> Any:
    """A progress bar for ``total`` steps on ``stream`` (stderr) if it is a terminal.

    Args:
        force: True/False to show/hide regardless of the terminal (tests).
    """
    stream = sys.stderr if stream is None else stream
    show = force if force is not None else bool(getattr(stream, "isatty", lambda: False)())
    if not show:
        return NoBar()
    return _Bar(total=total, desc=desc, unit=unit, file=stream, leave=False,
                dynamic_ncols=True, **kw)
