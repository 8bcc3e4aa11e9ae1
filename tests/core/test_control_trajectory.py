"""trajGen: limits respected, all DOFs arrive together, no overshoot, online re-targeting."""

import numpy as np
import pytest

from core import robots
from core.control.params import TrajectoryParams
from core.control.trajectory import TrajectoryGenerator

DT = 0.01


@pytest.fixture(scope="module")
def arm():
    return robots.load("soft-arm")


def roll(gen, max_steps=5000):
    samples = [gen.sample]
    for _ in range(max_steps):
        s = gen.update()
        samples.append(s)
        if s.finished:
            break
    pos = np.array([s.position for s in samples])
    vel = np.array([s.velocity for s in samples])
    acc = np.array([s.acceleration for s in samples])
    return pos, vel, acc, samples[-1]


@pytest.mark.parametrize("seed", range(4))
def test_limits_sync_and_no_overshoot(arm, seed):
    lim = TrajectoryParams.from_robot(arm)
    gen = TrajectoryGenerator(lim, DT, arm.kappa_max)
    rng = np.random.default_rng(seed)
    start = rng.uniform(-10, 10, 6)
    target = rng.uniform(-10, 10, 6)
    target[rng.integers(6)] = start[rng.integers(6)]  # some DOFs move little or not at all
    gen.reset(start)
    gen.set_target(target)
    pos, vel, acc, last = roll(gen)
    assert last.finished and np.allclose(pos[-1], target, atol=1e-9)
    tol = 1 + 1e-6
    assert np.all(np.abs(vel) <= lim.max_velocity * tol)
    assert np.all(np.abs(acc) <= lim.max_acceleration * tol)
    jerk = np.diff(acc, axis=0) / DT
    assert np.all(np.abs(jerk) <= lim.max_jerk * tol)
    # No overshoot: each DOF moves monotonically from start to target and never passes it.
    d = target - start
    progress = (pos - start) * np.sign(d)
    assert np.all(progress <= np.abs(d) + 1e-9)
    assert np.all(np.diff(progress, axis=0) >= -1e-9)
    # All DOFs arrive together: phase synchronisation makes the motion a straight line in kappa
    # space, so every DOF has covered the same fraction of its distance at every instant.
    moving = np.abs(d) > 1e-6
    frac = progress[:, moving] / np.abs(d[moving])
    assert np.allclose(frac, frac[:, :1], atol=1e-6)


def test_time_synchronisation_also_arrives_together(arm):
    lim = TrajectoryParams.from_robot(arm)
    lim = TrajectoryParams(lim.max_velocity * np.linspace(0.5, 1.5, 6), lim.max_acceleration,
                           lim.max_jerk, "time")
    gen = TrajectoryGenerator(lim, DT, arm.kappa_max)
    gen.set_target([1.0, -4.0, 8.0, 0.5, -2.0, 6.0])
    pos, _, _, _ = roll(gen)
    target = gen.target
    arrive = [np.flatnonzero(np.abs(pos[:, j] - target[j]) > 1e-6).max() + 1 for j in range(6)]
    assert max(arrive) - min(arrive) <= 1


def test_online_retarget_is_continuous_and_arrives(arm):
    lim = TrajectoryParams.from_robot(arm)
    gen = TrajectoryGenerator(lim, DT, arm.kappa_max)
    gen.set_target(np.full(6, 4.0))
    samples = [gen.update() for _ in range(80)]  # mid-motion
    gen.set_target(np.full(6, 9.0))  # pass over: further on in the same direction
    pos, vel, acc, last = roll(gen)
    pos = np.concatenate([[s.position for s in samples], pos])
    vel = np.concatenate([[s.velocity for s in samples], vel])
    assert last.finished and np.allclose(pos[-1], 9.0)
    # Continuity: no jumps larger than the limits allow in one period.
    assert np.all(np.abs(np.diff(pos, axis=0)) <= lim.max_velocity * DT * 1.001)
    assert np.all(np.abs(np.diff(vel, axis=0)) <= lim.max_acceleration * DT * 1.001)
    assert pos.max() <= 9.0 + 1e-9  # no overshoot at the new target


def test_hold_stops_the_reference(arm):
    gen = TrajectoryGenerator.from_robot(arm, DT)
    gen.set_target(np.full(6, 5.0))
    for _ in range(50):
        s = gen.update()
    gen.hold()
    assert np.allclose(gen.target, s.position)
    after = gen.update()
    assert np.allclose(after.position, s.position) and after.finished


def test_bad_target_is_refused_and_keeps_the_old_one(arm):
    gen = TrajectoryGenerator.from_robot(arm, DT)
    gen.set_target(np.full(6, 2.0))
    for bad in (np.full(6, arm.kappa_max + 1), np.full(5, 1.0), np.full(6, np.nan)):
        with pytest.raises(ValueError):
            gen.set_target(bad)
        assert np.allclose(gen.target, 2.0)
