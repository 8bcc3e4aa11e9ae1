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


class trial_progress:  # noqa: N801 - used like a function in a with statement
    """``with trial_progress(n) as progress:`` -- a ``progress(k, n, result)`` callback for
    :func:`core.control.trials.run_trials` that advances a bar (successes so far as postfix) on
    a terminal and does nothing otherwise."""

    def __init__(self, total: int, force: bool | None = None) -> None:
        self.bar = progress_bar(total, "trials", unit="trial", force=force)
        self.ok = 0

    def __call__(self, k: int, n: int, result: Any) -> None:
        self.ok += bool(getattr(result, "success", False))
        self.bar.set_postfix_str(f"{self.ok}/{k} ok", refresh=False)
        self.bar.update(1)

    def __enter__(self) -> trial_progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.bar.close()


class row_progress:  # noqa: N801 - used like a function in a with statement
    """``with row_progress("capture grid") as progress:`` -- a ``progress(done, total)``
    callback (``core.control.capture.characterise``) driving a bar on a terminal only."""

    def __init__(self, desc: str, force: bool | None = None) -> None:
        self.bar = progress_bar(None, desc, unit="row", force=force)

    def __call__(self, done: int, total: int) -> None:
        self.bar.total = total
        self.bar.update(done - self.bar.n)

    def __enter__(self) -> row_progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.bar.close()
