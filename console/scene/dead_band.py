"""What the arm view leaves unsent: a dead band on the drawn frames, so a still arm costs ~0.

:class:`DeadBand` decides whether the drawn frames left the band around the last frame sent,
compared on a running average whose time constant shrinks while the frames move steadily
(:class:`Steadiness`): measurement noise averages out, a real move is drawn at once. Used by
:class:`console.scene.arm_view.ArmView`; pure numpy.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class DeadBand:
    """A frame is sent only when what is drawn moved more than this since the last sent frame.

    The comparison uses the drawn frames smoothed over ``settle_s`` (an exponential average in
    time): motion-capture noise of a still arm averages out instead of crossing the band (the
    soft arm's curvatures from the simulator's 0.2 mm marker noise move its gripper's end by a
    few mm rms: a band below that noise alone would send every frame). The time constant shrinks
    (from ``moving_settle_s``) to 0 as the frames move steadily (:class:`Steadiness`), so a jog
    or a planned move is drawn at once. What is sent is always the newest frame, never the
    average; a frame held back is sent once the display goes idle (:meth:`ArmView.flush`). Defaults: 1 mm (about two pixels
    of a 0.5 m arm in an 800 px view) and 1 deg, averaged over 4 s: a still soft arm on the
    simulator is drawn ~2-5 times a minute (``benchmarks/dead_band_noise.py``; 75 a minute with
    0.5 mm over 2 s and any momentary steadiness counted as a move).

    While the frames move steadily (steadiness at least ``moving_steadiness`` for
    ``moving_frames`` updates in a row: a jog, a planned move) the band is ``moving_position``
    / ``moving_angle`` instead: the still band let a grasp-and-place approach (the soft arm's
    points move at a few mm/s) through only every 3rd to 4th frame, ~10 frames/s
    (``benchmarks/arm_frames_replay.py``). A still arm's noise is not steady: its steadiness
    reads ~0.1-0.2 and seldom passes 0.5, hardly ever several updates in a row.

    Args:
        position: Largest unsent translation (m).
        angle: Largest unsent rotation (rad).
        settle_s: Time constant of the average (s); 0 compares the newest frames themselves.
        moving_settle_s: Time constant (s) at steadiness 0 of the one that shrinks with a
            steady move (:meth:`average`).
        moving_position: Largest unsent translation while the frames move steadily (m).
        moving_angle: Largest unsent rotation while the frames move steadily (rad).
        moving_steadiness: Steadiness (:class:`Steadiness`) from which the frames move.
        moving_frames: Updates in a row at ``moving_steadiness`` or more before the moving band
            applies.
        moving_steps: Fewest steps the steadiness must be measured over since it started
            afresh (after a pause its first steps read as steady, noise included).
        steadiness_s: Time constant (s) over which the steadiness is measured
            (:class:`Steadiness`; why 0.75 s there).
        jump: Distance (m) of the newest frames from the average beyond which they jumped
            (:meth:`jumped`): the average and the steadiness start afresh from them. Else the
            average's catch-up was drawn ~1 frame/s for ~10 s after the arm stood still again,
            and the jump's one step read as a steady move for ~2 s, every noisy frame drawn
            (``benchmarks/bench_viewers.py``, extensible still: 1.0 frame/s). 20 mm: several
            times the largest noise (the soft arm's gripper end, a few mm rms) and more than any
            arm moves between two drawn frames.
        jump_angle: The same for rotations (rad).
    """

    position: float = 1e-3
    angle: float = float(np.deg2rad(1.0))
    settle_s: float = 4.0
    moving_settle_s: float = 2.0
    moving_position: float = 1e-4
    moving_angle: float = float(np.deg2rad(0.1))
    moving_steadiness: float = 0.5
    moving_steps: int = 8
    steadiness_s: float = 0.75
    moving_frames: int = 5
    jump: float = 2e-2
    jump_angle: float = float(np.deg2rad(20.0))

    def moved(self, sent: Array, now: Array, steadiness: float = 0.0) -> bool:
        """Whether any of the (P, 4, 4) frames ``now`` left the band around ``sent`` (the
        moving band when ``steadiness`` reaches ``moving_steadiness``)."""
        if sent.shape != now.shape:
            return True
        moving = steadiness >= self.moving_steadiness
        return _apart(sent, now, self.moving_position if moving else self.position,
                      self.moving_angle if moving else self.angle)

    def jumped(self, mean: Array, now: Array) -> bool:
        """Whether any of the frames ``now`` is more than ``jump`` / ``jump_angle`` away from the
        average ``mean``: a jump (a replay seek, a device connecting, a source that switched),
        neither noise nor a move between two frames."""
        return mean.shape != now.shape or _apart(mean, now, self.jump, self.jump_angle)

    def average(self, mean: Array | None, frames: Array, dt: float, steadiness: float = 0.0,
                ) -> Array:
        """The running average of the frames after ``dt`` seconds more of ``frames``.

        ``steadiness`` in [0, 1] (1: the frames move steadily one way, 0: they jitter) from
        ``moving_steadiness`` on sets the time constant to ``moving_settle_s (1 - steadiness)`` (at most ``settle_s``),
        so a real move is not delayed; below it the frames are noise (a still arm's measurement
        noise reads ~0.15) and are averaged over the whole ``settle_s``.
        """
        s = min(max(steadiness, 0.0), 1.0)
        tau = self.settle_s
        if s >= self.moving_steadiness:
            tau = min(tau, self.moving_settle_s * (1.0 - s))
        if mean is None or mean.shape != frames.shape or tau <= 1e-6:
            return frames.copy()
        alpha = 1.0 - np.exp(-max(dt, 0.0) / tau)
        return mean + alpha * (frames - mean)


def _apart(a_frames: Array, b_frames: Array, position: float, angle: float) -> bool:
    """Whether any of the (P, 4, 4) frames ``b_frames`` is more than ``position`` (m) or
    ``angle`` (rad) away from the same frame of ``a_frames``."""
    if np.abs(b_frames[:, :3, 3] - a_frames[:, :3, 3]).max(initial=0.0) > position:
        return True
    # For rotations R_a, R_b: trace(R_a^T R_b) = 1 + 2 cos(angle between them), and
    # |R|_F = sqrt(3). Scaled by the norms so that averaged (shrunk) rotations compare too.
    a, b = a_frames[:, :3, :3], b_frames[:, :3, :3]
    dot = np.einsum("pij,pij->p", a, b)
    norms = np.linalg.norm(a, axis=(1, 2)) * np.linalg.norm(b, axis=(1, 2))
    cos = (3.0 * dot / norms - 1.0) / 2.0
    return bool(np.any(cos < np.cos(angle)))


class Steadiness:
    """How steadily the drawn frames move: |mean step| / mean |step| over ~``tau`` seconds.

    About 1 for a move (every step points the same way), about sqrt(dt / 2 tau) for noise.
    ``steps``: how many steps it is measured over (a first step alone reads 1: it cannot yet
    tell a move from noise); the first ``tau / dt`` steps are averaged with equal weights (a
    plain mean, then the exponential one), so n steps of noise read ~1/sqrt(n) from the start
    instead of the first step's weight keeping them "steady" for ~``tau``. After a pause of
    over ``5 tau`` it starts afresh from the frames that end it: a step across a pause from a
    noisy frame made a clean move after it read as noise for a dozen updates.

    ``tau`` (the arm view's: ``DeadBand.steadiness_s``) 0.75 s: an armed soft arm holding still measures curvatures whose steps correlate
    (the controller acts on the motion capture's noise; lag-1 ~0.25), and over 0.25 s such
    noise read as a steady move for 5 updates in a row a few times a minute, each drawn through
    the moving band (emulator: 4 frames/min; 0.75 s: ~1/min, 4 minutes of it replayed). The
    price: after a move ends its steadiness takes ~0.5 s longer to fall (~6 more frames).
    """

    def __init__(self, tau: float) -> None:
        self.tau = tau
        self.steps = 0
        self._last: Array | None = None
        self._drift: Array | None = None
        self._jitter = 0.0

    def update(self, frames: Array, dt: float) -> float:
        pos = frames[:, :3, 3].ravel()
        last, self._last = self._last, pos.copy()
        if last is None or last.shape != pos.shape:
            self._drift, self._jitter, self.steps = None, 0.0, 0
            return 1.0
        if dt > 5 * self.tau:  # after a pause: start afresh from here (the step across a
            self._drift, self._jitter, self.steps = None, 0.0, 0  # pause is no move's step)
            return 1.0
        step = pos - last
        alpha = 1.0 - np.exp(-max(dt, 1e-6) / self.tau)
        if self._drift is None:
            self._drift, self._jitter = step.copy(), float(np.linalg.norm(step))
            self.steps = 1
        else:
            self.steps += 1
            alpha = max(alpha, 1.0 / self.steps)
            self._drift += alpha * (step - self._drift)
            self._jitter += alpha * (float(np.linalg.norm(step)) - self._jitter)
        if self._jitter <= 1e-12:
            return 1.0
        return float(np.linalg.norm(self._drift)) / self._jitter
