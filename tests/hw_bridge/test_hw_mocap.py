"""Motion capture sources: packet round trip, staleness, replay timing, UDP receiver, NatNet."""

from __future__ import annotations

import socket
import sys
import threading
import time

import numpy as np
import pytest

from hw_bridge import mocap as m
from hw_bridge.plants import CurvaturePlant, MotorBank


def test_packet_round_trip_and_rejects_garbage() -> None:
    pts = np.arange(21, dtype=float).reshape(7, 3)
    f = m.decode_mocap_packet(m.encode_mocap_packet(9, 1.5, pts, True), 2.0)
    assert f is not None and f.seq == 9 and f.t_capture == 1.5 and f.t_received == 2.0 and f.valid
    np.testing.assert_array_equal(f.points, pts)
    good = m.encode_mocap_packet(1, 0.0, pts, True)
    assert m.decode_mocap_packet(good[:-1], 0.0) is None
    assert m.decode_mocap_packet(b"XXXX" + good[4:], 0.0) is None
    assert m.decode_mocap_packet(b"", 0.0) is None


def test_frame_health() -> None:
    pts = np.zeros((2, 3))
    f = m.MocapFrame(1, 0.0, 10.0, pts, True)
    assert m.frame_health(None, 10.0) == "missing"
    assert m.frame_health(f, 10.049) == "ok"
    assert m.frame_health(f, 10.051) == "stale"
    assert m.frame_health(m.MocapFrame(1, 0.0, 10.0, pts, False), 10.0) == "invalid"
    assert m.frame_health(m.MocapFrame(1, 0.0, 10.0, np.full((2, 3), np.nan), True), 10.0) == "invalid"


def test_udp_receiver_latest_never_blocks_and_counts_bad_packets() -> None:
    rx = m.UdpMocapReceiver(0)
    rx.start()
    try:
        # Nothing was sent yet: a latest() that waited for a packet would never return. (How
        # long it takes is a figure: benchmarks/mocap_latest.py.)
        got: list[object] = []
        reader = threading.Thread(target=lambda: got.append(rx.latest()), daemon=True)
        reader.start()
        reader.join(timeout=20)
        assert not reader.is_alive() and got == [None]
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sent_at = time.monotonic()
        s.sendto(b"garbage", rx.addr)
        s.sendto(m.encode_mocap_packet(5, 0.0, np.ones((3, 3)), True), rx.addr)
        end = time.monotonic() + 20
        while rx.latest() is None and time.monotonic() < end:
            time.sleep(0.005)
        f = rx.latest()
        assert f is not None and f.seq == 5 and rx.bad_packets == 1
        # Stamped on arrival on this host's monotonic clock (its age is what frame_health
        # judges; asking at once would be a race with a stall of the test's thread).
        assert sent_at <= f.t_received <= time.monotonic()
        assert m.frame_health(f, f.t_received + 0.01) == "ok"
        s.close()
    finally:
        rx.stop()


def test_replay_follows_recorded_timing(tmp_path) -> None:
    t = np.array([0.0, 0.1, 0.2, 0.3])
    frames = [m.MocapFrame(i, float(t[i]), 0.0, np.full((2, 3), float(i)), i != 2) for i in range(4)]
    path = tmp_path / "rec.npz"
    m.save_recording(path, frames)
    now = [100.0]
    rp = m.ReplayMocap(path, loop=False, clock=lambda: now[0])
    assert rp.latest() is None
    rp.start()
    now[0] = 100.13
    f = rp.latest()
    assert f is not None and f.points[0, 0] == 1.0 and f.t_received == pytest.approx(100.1)
    assert m.frame_health(f, now[0]) == "ok"
    now[0] = 100.25
    assert m.frame_health(rp.latest(), now[0]) == "invalid"
    now[0] = 100.5  # past the end without looping: last frame goes stale
    f = rp.latest()
    assert f.points[0, 0] == 3.0 and m.frame_health(f, now[0]) == "stale"
    loop = m.ReplayMocap(path, loop=True, clock=lambda: now[0])
    loop.start()
    now[0] += 0.35  # 0.35 mod 0.3 = 0.05 -> frame 0
    assert loop.latest().points[0, 0] == 0.0


def test_natnet_missing_gives_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "natnet", None)  # makes "import natnet" raise ImportError
    with pytest.raises(ImportError, match="optional 'natnet' package"):
        m.NatNetMocap("127.0.0.1", [1])


def test_curvature_plant_is_an_exact_first_order_lag() -> None:
    fk_calls = []
    plant = CurvaturePlant(2, counts_per_kappa=50.0, tau=0.2, kappa_max=10.0,
                           forward_kinematics=lambda k: fk_calls.append(k) or np.zeros((3, 3)))
    cyl = np.array([250.0, 0.0, 0.0, 1000.0, 77.0])  # seg0: +5 1/m, seg1: -20 -> clipped to -10
    np.testing.assert_allclose(plant.steady_state(cyl), [5.0, -10.0])
    plant.step(cyl, 0.1)
    np.testing.assert_allclose(plant.kappa, np.array([5.0, -10.0]) * (1 - np.exp(-0.5)))
    for _ in range(10):
        plant.step(cyl, 0.1)
    np.testing.assert_allclose(plant.kappa, np.array([5.0, -10.0]) * (1 - np.exp(-5.5)))
    plant.shape()
    np.testing.assert_array_equal(fk_calls[-1], plant.kappa)


def test_motor_bank_speed_limit_and_disable() -> None:
    bank = MotorBank(2, 100.0)
    bank.set_targets(0b11, (50, -500))
    bank.step(0.1)
    np.testing.assert_array_equal(bank.position, [0, 0])  # disabled: no motion
    bank.enabled = True
    bank.step(0.1)
    np.testing.assert_allclose(bank.position, [10, -10])
    for _ in range(10):
        bank.step(0.1)
    np.testing.assert_allclose(bank.position, [50, -110])
    with pytest.raises(ValueError, match="mask selects"):
        bank.set_targets(0b1, (1, 2))
