"""Why a rerun test failed the first time, in the suite's output, so a CI flake can be diagnosed.

scripts/test reruns a failing browser or timing test once (pytest-rerunfailures, ``--reruns 1
-rR``); its summary lists only ``RERUN <test>``, and the first failure's traceback is dropped.
This plugin (registered by tests/conftest.py's ``pytest_plugins``) keeps each report whose
outcome is ``"rerun"`` and

* says at once, on its own line, which test is rerun and its failure's one-line message
  (a run cut short by a CI time limit still shows it);
* prints a ``rerun reasons`` section in the terminal summary: for every rerun attempt the test,
  the phase and duration, the failure message, the last :data:`TAIL_LINES` lines of its
  traceback and the last :data:`CAPTURED_LINES` lines of what it wrote to stderr.
"""

from __future__ import annotations

import dataclasses

import pytest

TAIL_LINES = 30
CAPTURED_LINES = 10


@dataclasses.dataclass(frozen=True)
class RerunReason:
    """One failed attempt that was run again."""

    nodeid: str
    when: str
    duration_s: float
    message: str
    traceback_tail: tuple[str, ...]
    stderr_tail: tuple[str, ...]

    @classmethod
    def of(cls, report: pytest.TestReport) -> RerunReason:
        text = "" if report.longrepr is None else str(report.longrepr)
        lines = text.rstrip().splitlines()
        crash = getattr(report.longrepr, "reprcrash", None)
        message = getattr(crash, "message", None) or (lines[-1] if lines else "(no traceback)")
        stderr = [line for title, content in report.sections if "stderr" in title
                  for line in content.rstrip().splitlines()]
        return cls(report.nodeid, report.when or "?", float(report.duration or 0.0),
                   message.strip(), tuple(lines[-TAIL_LINES:]), tuple(stderr[-CAPTURED_LINES:]))

    def headline(self) -> str:
        first = self.message.splitlines()[0] if self.message else ""
        return f"RERUN {self.nodeid} ({self.when}, {self.duration_s:.1f} s): {first}"


class RerunReasons:
    """Collects the ``rerun`` reports of one session and prints their reasons."""

    def __init__(self, config: pytest.Config) -> None:
        self.config = config
        self.reasons: list[RerunReason] = []

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        if report.outcome != "rerun":
            return
        reason = RerunReason.of(report)
        self.reasons.append(reason)
        tr = self.config.pluginmanager.get_plugin("terminalreporter")
        if tr is not None:  # on a line of its own, after the progress characters
            tr.write_line("")
            tr.write_line(reason.headline(), yellow=True)

    def pytest_terminal_summary(self, terminalreporter: pytest.TerminalReporter) -> None:
        if not self.reasons:
            return
        tr = terminalreporter
        tr.write_sep("=", "rerun reasons (the first failure of each rerun test)", yellow=True)
        for reason in self.reasons:
            tr.write_line(reason.headline(), yellow=True, bold=True)
            for line in reason.traceback_tail:
                tr.write_line(f"    {line}")
            if reason.stderr_tail:
                tr.write_line(f"    --- last {len(reason.stderr_tail)} lines of its stderr ---")
                for line in reason.stderr_tail:
                    tr.write_line(f"    {line}")


def pytest_configure(config: pytest.Config) -> None:
    config.pluginmanager.register(RerunReasons(config), "rerun-reasons")
