"""The extensible emulator's ``--mid-range`` start: its encoders read the console's start pose
(straight, racks mid-range), so connecting and arming the console moves nothing."""

from __future__ import annotations

import os

import numpy as np
import pytest

from console.core.model import model_for
from core.robots import load
from hw_bridge.emulator import options_from_args, parse_args
from hw_bridge.extensible_jobs import home_counts, measure
from hw_bridge.pty_emulator import Emulator

EXT = load("extensible")


def emulator(*argv: str) -> Emulator:
    return Emulator(load(argv[1]), options_from_args(parse_args(list(argv))), lambda *a, **k: None)


@pytest.mark.parametrize("extra", [(), ("--slip", "0.1")])
def test_mid_range_start_reads_the_consoles_start_pose(extra) -> None:
    emu = emulator("--robot", "extensible", "--mid-range", *extra)
    try:
        _, delta, _ = measure(EXT, emu.core.motors.encoders, home_counts(EXT))
        start = model_for(EXT).initial()
        assert start[:, 2].min() > 0  # mid-range: room to bend, not retracted
        np.testing.assert_allclose(delta, start, atol=2e-5)  # within an encoder count or so
        if emu.racks is not None:  # the racks are there too: nothing slipped getting there
            np.testing.assert_allclose(emu.racks.lengths,
                                       measure(EXT, emu.core.motors.encoders, home_counts(EXT))[0],
                                       atol=2e-5)
    finally:
        os.close(emu.master)


def test_without_the_flag_the_racks_power_up_retracted() -> None:
    emu = emulator("--robot", "extensible")
    try:
        assert not emu.core.motors.encoders.any()
    finally:
        os.close(emu.master)


def test_mid_range_is_refused_for_the_soft_arm() -> None:
    with pytest.raises(ValueError, match="extensible"):
        emulator("--robot", "soft-arm", "--mid-range")
