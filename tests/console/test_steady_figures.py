"""Steady figures and counter rates (console.panels.common.steady_figures): what a live readout
shows of a jittering measurement and of an ever-growing counter."""

from __future__ import annotations

import math

import numpy as np
import pytest

from console.panels.common.steady_figures import CountRate, SteadyFigure


def test_a_steady_figure_follows_only_moves_past_its_band() -> None:
    fig = SteadyFigure(rel=0.25, floor=0.1)
    assert fig.shown(None) is None
    assert fig.shown(1.0) == 1.0
    rng = np.random.default_rng(0)
    assert {fig.shown(1.0 + d) for d in rng.uniform(-0.24, 0.24, 200)} == {1.0}
    assert fig.shown(1.3) == 1.3  # 30 % > 25 %: followed
    assert fig.shown(0.05) == 0.05  # back down
    assert fig.shown(0.14) == 0.05  # near 0 the floor (0.1) holds it
    assert fig.shown(math.nan) is None and fig.shown(0.14) == 0.14  # nothing measured: at once
    with pytest.raises(ValueError):
        SteadyFigure(rel=-1.0)


def test_count_rate_of_a_100_hz_counter_read_unevenly() -> None:
    rate = CountRate(window_s=2.0)
    rng = np.random.default_rng(1)
    t, count, rates = 0.0, 0, []
    for _ in range(200):
        dt = rng.uniform(0.2, 0.3)  # a 4 Hz refresh that jitters
        t += dt
        count += int(round(100 * dt))  # whole messages
        rates.append(rate.rate(t, count))
    assert rates[:6] == [None] * 6  # < 2 s of reads
    known = np.array([r for r in rates if r is not None])
    assert len(known) > 180 and np.all(np.abs(known - 100.0) < 3.0)
    assert rate.rate(t + 0.25, count + 25) == pytest.approx(100.0, abs=3.0)
    assert rate.rate(t + 0.5, 3) is None  # the counter went back (a new link): starts afresh
    assert rate.rate(t + 2.5, 3) == 0.0  # nothing received for 2 s


def test_count_rate_window_must_be_positive() -> None:
    with pytest.raises(ValueError):
        CountRate(window_s=0.0)
