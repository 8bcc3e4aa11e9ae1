"""How long an operator's tab may stay silent before the arm stops, from measured browsers.

The limits of the operator lock's lease (``console.core.access.AccessControl``: ``lease_s``,
``warn_s``, ``first_answer_s``) with the measurements they come from, and
:class:`LeaseStatus`, the lease at one instant with the sentence its holder reads
(``console.lease.LeaseMonitor`` shows it on their tab).
"""

from __future__ import annotations

import dataclasses

from console.core.operator import Operator

# The lease's limits, from benchmarks/lease_gaps.py (headless Chromium 1280x800 or a tablet:
# 820x1180 touch viewport with 4x CPU throttling; software rendering; the console streaming a
# moving arm; probe every 0.1 s; 2 cores already shared with other work; s):
#
#                                  gaps between answers (n)          connect -> first answer
#                                  p50   p99   p99.9  max            max of 2-3 fresh tabs
#   desktop                        0.34  0.97  1.05   1.06  (80)     1.96
#   desktop, 2 busy loops          0.30  1.07  3.16   3.40  (106)    2.78
#   tablet                         1.40  3.20  3.20   3.20  (22)     9.67
#   tablet, 2 busy loops           0.67  1.51  1.60   1.61  (39)     8.66
#
# The old limits lapsed on these browsers: a 2 s lease against gaps of 3.4 s, a 10 s grace
# against first answers of 9.7 s (the tablet of issue #19). LEASE_S is the worst gap x 2
# (3.4 s -> 7 s); FIRST_ANSWER_S the slowest first answer x 2 (9.7 s -> 20 s); WARN_S, half
# the lease, is past every gap measured, so a warning means something unusual. What does not
# wait for the lease: a held jog or set-point move holds 300 ms after the last answer
# (console.core.hold_to_run), a closed tab is revoked at once, STOP works from every browser.
LEASE_S = 7.0
WARN_S = 3.5
FIRST_ANSWER_S = 20.0


@dataclasses.dataclass(frozen=True)
class LeaseStatus:
    """The operator's lease at one instant (see :meth:`AccessControl.status`).

    Attributes:
        holder: Who holds control (None: nobody, and the rest means nothing).
        silent_for: Seconds since their tab last answered (or took control).
        limit: Silence after which control is revoked (``lease_s``, or ``first_answer_s``
            while the tab has not answered yet).
        warn_after: Silence after which the operator is warned.
        answered: Whether their tab has answered at all (False: the page is still loading).
    """

    holder: Operator | None
    silent_for: float
    limit: float
    warn_after: float
    answered: bool

    @property
    def warning(self) -> bool:
        """Whether the operator should be warned now: a tab that answered before and has been
        silent for ``warn_after`` s (a page still loading is in its grace, not warned)."""
        return self.holder is not None and self.answered and self.silent_for >= self.warn_after

    def sentence(self) -> str:
        """What the operator reads: how long their browser has been silent, when the arm stops."""
        return (f"Your browser has been silent for {self.silent_for:.1f} s; the arm stops at "
                f"{self.limit:g} s. Close other busy tabs or programs.")
