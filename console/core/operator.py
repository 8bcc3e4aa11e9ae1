"""Who holds control of the arm, apart from the lock that grants it: the lock's and lease's.

:class:`Operator` is what :class:`console.core.access.AccessControl` grants and what a
:class:`console.core.lease_limits.LeaseStatus` names as its holder; it lives below both so
neither imports the other back.
"""

from __future__ import annotations

import dataclasses


@dataclasses.dataclass(frozen=True)
class Operator:
    """Who holds control: the viser client id, the name they gave, and since when (epoch s)."""

    client_id: int
    name: str
    since: float
