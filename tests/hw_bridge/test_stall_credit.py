"""The host's own stall credit (hw_bridge.stall_credit.OwnStall) against hand-counted reads."""

from __future__ import annotations

import pytest

from hw_bridge.stall_credit import OwnStall


def test_a_late_read_is_credited_beyond_one_period_and_a_new_state_starts_again() -> None:
    stall = OwnStall(0.01)
    for t in (0.01, 0.02, 0.03):            # punctual reads of a STATE received at 0
        assert stall.credit(t, 0.0) == 0.0
    assert stall.credit(0.09, 0.0) == pytest.approx(0.05)        # 60 ms gap: 50 ms beyond
    assert stall.credit(0.10, 0.0) == pytest.approx(0.05)        # punctual again: kept
    assert stall.credit(0.16, 0.0) == pytest.approx(0.10)        # another 50 ms: added
    assert stall.credit(0.17, 0.165) == 0.0                      # a newer STATE: from zero
    # A late STATE's read counts from the STATE, not from the read before it.
    assert stall.credit(0.23, 0.165) == pytest.approx(0.23 - 0.17 - 0.01)


def test_jitter_is_not_a_stall_and_reset_forgets() -> None:
    stall = OwnStall(0.01)
    stall.credit(0.01, 0.0)
    assert stall.credit(0.0249, 0.0) == 0.0       # 4.9 ms late: under half a period
    assert stall.credit(0.0400, 0.0) == pytest.approx(0.0051)   # 5.1 ms late: credited
    assert stall.credit(0.05, None) == pytest.approx(0.0)  # no STATE yet: nothing to credit
    stall.reset()
    assert stall.credit(0.2, 0.0) == 0.0          # the first read after a reset: no gap yet
