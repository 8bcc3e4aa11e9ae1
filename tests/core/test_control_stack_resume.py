"""The control stack's resume path never aims beyond the curvature limit |kappa| <= kappa_max.

The stack restarts trajGen from the *measured* curvature (on arming, after a freeze), and a
measurement may lie beyond the limit (an arm bent past it by hand or by a load, or motion-capture
noise at full bend). A freeze (tracking lost, STOP) keeps that state as the target to resume to;
the resume then handed it to ``trajGen.set_target``, which refuses anything beyond the limit, so
the period raised and the loop faulted. Expected here, independently of the stack's code: the
update goes on, every target and reference stays within +-kappa_max, and each resume target is
the measurement clamped to the limit (per segment, sign kept).
"""

import dataclasses

import numpy as np
import pytest

from core import robots
from core.control.grasp_place import immediate
from core.control.stack import ControlStack
from core.kinematics.planar import forward_kinematics

ARM = robots.load("soft-arm")
KMAX = ARM.kappa_max


@dataclasses.dataclass
class _Reading:
    markers: np.ndarray
    object_xy: np.ndarray | None = None
    object_radius: float | None = None


def _markers(kappa):
    """Segment-end markers of the arm at ``kappa`` (exact forward kinematics, no noise)."""
    return forward_kinematics(np.asarray(kappa, float), ARM.lengths, ARM.base_pose)[1:, :2]


def _never_plans(req):
    raise AssertionError("no plan is asked for in these tests")


def _stack():
    return ControlStack(ARM, 0.01, immediate(_never_plans))


# Past the limit on the first and last segments (both signs), within it elsewhere.
BEYOND = np.array([KMAX + 0.6, 3.0, -2.0, 0.0, 1.0, -(KMAX + 0.4)])[: ARM.n_segments]


def _armed_beyond(stack, t=0.0):
    reading = _Reading(_markers(BEYOND))
    stack.update(reading, t)
    meas = stack.kappa_meas
    assert meas is not None and np.abs(meas).max() > KMAX + 0.3  # the measurement is beyond
    stack.arm()
    return reading, meas


def _assert_within(stack):
    assert np.all(np.abs(stack.traj.target) <= KMAX + 1e-9), stack.traj.target


def test_arming_beyond_the_limit_aims_at_the_limit():
    stack = _stack()
    _, meas = _armed_beyond(stack)
    np.testing.assert_allclose(stack.traj.target, np.clip(meas, -KMAX, KMAX), atol=1e-12)


def test_tracking_lost_then_back_resumes_within_the_limit():
    stack = _stack()
    reading, meas = _armed_beyond(stack)
    t = 0.01
    stack.update(reading, t)
    stack.machine.start(t)  # settling: a task runs, so lost tracking freezes the cylinders
    hidden = _Reading(np.full((ARM.n_segments, 2), np.nan))
    for _ in range(5):
        t += 0.01
        _, tel = stack.update(hidden, t)
        assert not tel.tracking_ok
    assert stack._freeze
    for _ in range(20):  # tracking is back: resume toward the (clamped) target, no exception
        t += 0.01
        commands, tel = stack.update(reading, t)
        assert commands is not None and tel.tracking_ok
        _assert_within(stack)
    np.testing.assert_allclose(stack.traj.target, np.clip(meas, -KMAX, KMAX), atol=1e-9)


def test_stop_then_tracking_resumes_within_the_limit():
    stack = _stack()
    reading, _ = _armed_beyond(stack)
    stack.update(reading, 0.01)
    stack.stop(0.02)
    for k in range(20):
        commands, tel = stack.update(reading, 0.03 + 0.01 * k)
        assert commands is not None and tel.phase == "stopped"
        _assert_within(stack)
    # And the operator can move away again afterwards.
    stack.goto(np.zeros(ARM.n_segments), 0.5)
    np.testing.assert_allclose(stack.traj.target, 0.0)


def test_goto_beyond_the_limit_is_still_refused_and_moves_nothing():
    stack = _stack()
    reading, _ = _armed_beyond(stack)
    stack.update(reading, 0.01)
    before = stack.traj.target.copy()
    with pytest.raises(ValueError, match="beyond"):
        stack.goto(np.full(ARM.n_segments, KMAX + 1.0), 0.02)
    np.testing.assert_array_equal(stack.traj.target, before)


def test_trajgen_reset_beyond_the_limit_holds_the_limit_and_moves_back():
    """trajGen restarted at a state past the limit (the stack's restarts and holds do that)
    takes the state as the reference and aims at it clamped, then gets there."""
    stack = _stack()
    gen = stack.traj
    gen.reset(BEYOND)
    np.testing.assert_allclose(gen.sample.position, BEYOND)
    np.testing.assert_allclose(gen.target, np.clip(BEYOND, -KMAX, KMAX))
    assert not gen.sample.finished
    for _ in range(300):
        sample = gen.update()
    assert sample.finished
    np.testing.assert_allclose(sample.position, np.clip(BEYOND, -KMAX, KMAX), atol=1e-9)
