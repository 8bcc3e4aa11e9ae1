"""Hold-to-run jogging with server-side speed caps, so a lost tab or stuck button cannot move it.

:class:`HoldToRun` owns every jog motion of the console. It is fed by GUI callbacks and moves
the commanded configuration itself, at ``rate_hz``, from its own thread:

* :meth:`HoldToRun.hold` starts (or renews) a jog of one coordinate in one direction. A jog
  runs only while renewals keep arriving: each one expires ``expiry`` s (300 ms) after it was
  sent, so a released button, a closed tab or a dropped network stops it within that time.
  The jog buttons renew it from viser's ``on_hold`` (sent by the browser while the button is
  pressed); releasing the button ends it at once.
* :meth:`HoldToRun.move_to` moves towards a set-point (the jog sliders, Straighten/Retract).
  It too runs only while heartbeats arrive: a step is taken only if the client was heard from
  (the request itself, or a lease probe answer: ``heard(client)``, see ``console.core.access``) less
  than ``expiry`` s ago; otherwise the arm holds where it is until the next answer, and the
  move ends for good when the client loses its operator lease (``allowed(client)``), on STOP
  or when someone else commands the arm.

Both are capped on the server: every step is clamped to the robot's soft limits
(``ArmModel.set_coordinate`` / ``clamp``) and scaled down so that no point of the arm (segment
ends and, on the soft arm, the gripper's far end) moves faster than ``tip_speed`` (250 mm/s),
measured with the forward kinematics of ``core.kinematics``. The Jog panel's motions (held jogs,
and set-points asked for with ``move_to(..., jog=True)``: its sliders, Straighten, Retract) are
slower still: no arm point faster than the operator's *jog speed* (:attr:`HoldToRun.jog_speed`,
set with :meth:`HoldToRun.set_jog_speed` within :attr:`HoldToRun.jog_speed_limits`; the console
core starts it at the arm model's ``jog_speed``: 20 mm/s on the extensible arm, a speed a class
can follow). :meth:`HoldToRun.cancel` (STOP, a
lost lease) ends all motion and latches: a button still held keeps renewing into nothing until
it is released (its click arrives on mouse-up) and pressed again, or has sent no renewal for
``latch_gap`` s (a release whose click never arrived). A held jog that ends because its renewals
stopped (not a release) is reported to ``on_expired``: the console core
(``console.core.console_core``) makes it a stop through its one safety route.
"""

from __future__ import annotations

import dataclasses
import math
import threading
import time
from typing import Callable

import numpy as np
import numpy.typing as npt

from console.core.model import ArmModel, Coordinate, ExtensibleModel, SoftArmModel
from console.core.state import ArmState, StateStore
from core.kinematics import delta as dk
from core.kinematics import planar as pk
from core.units import fmt_mm

Array = npt.NDArray[np.float64]
HOLD_SOURCE = "jog-hold"
MOVE_SOURCE = "jog"
STOP_SOURCE = "stop"
JOG_SPEED_MIN = 0.001  # m/s: the slowest jog speed an operator may set (1 mm/s)


def arm_points(model: ArmModel, q: npt.ArrayLike) -> Array:
    """Points whose speed is capped, (..., k, 3): segment ends (+ gripper far end), metres."""
    q = np.asarray(q, dtype=float)
    if isinstance(model, SoftArmModel):
        r = model.robot
        poses = pk.forward_kinematics(q, r.lengths, r.base_pose)  # (..., N+1, 3)
        tip = poses[..., -1, :]
        far = tip[..., :2] + r.gripper.length * np.stack([np.cos(tip[..., 2]),
                                                          np.sin(tip[..., 2])], axis=-1)
        xy = np.concatenate([poses[..., 1:, :2], far[..., None, :]], axis=-2)
        return np.concatenate([xy, np.zeros(xy.shape[:-1] + (1,))], axis=-1)
    if isinstance(model, ExtensibleModel):
        r = model.robot
        return dk.forward_kinematics(q, r.L0, r.d)[..., 1:, :3, 3]
    raise TypeError(f"no arm points for {type(model).__name__}")


def largest_displacement(model: ArmModel, qa: npt.ArrayLike, qb: npt.ArrayLike) -> float:
    """Largest distance any capped point moves between configurations ``qa`` and ``qb``."""
    return float(np.max(np.linalg.norm(arm_points(model, qb) - arm_points(model, qa), axis=-1)))


def limit_step(model: ArmModel, q: Array, goal: Array, max_disp: float) -> Array:
    """The furthest configuration from ``q`` towards ``goal`` whose points move <= ``max_disp``."""
    full = largest_displacement(model, q, goal)
    if full <= max_disp:
        return goal
    s = max_disp / full
    for _ in range(50):
        cand = q + s * (goal - q)
        disp = largest_displacement(model, q, cand)
        if disp <= max_disp:
            return cand
        s *= 0.95 * max_disp / disp
    return q.copy()


@dataclasses.dataclass
class _Hold:
    client_id: int
    coord: Coordinate
    direction: int
    renewed: float


@dataclasses.dataclass
class _Move:
    client_id: int
    target: Array
    requested: float  # clock time of the request (the first sign of life)
    jog: bool = False  # a Jog panel set-point: at the jog speed


class HoldToRun:
    """Jog motions of the console (see the module docstring).

    Args:
        store: Where the commanded configuration lives.
        allowed: ``allowed(client_id)``: may this client still move the arm (holds the lease)?
        heard: ``heard(client_id)``: clock time this client's tab last answered (None: never).
            A set-point move steps only while that, or its request, is less than ``expiry``
            old. None: set-point moves need no heartbeat (programmatic use, tests).
        expiry: A hold not renewed for this long stops; a set-point move without a heartbeat
            for this long holds (s).
        tip_speed: Largest speed of any arm point (m/s).
        jog_speed: Largest speed of any arm point in held jogs and ``jog=True`` set-points
            (m/s), within :attr:`jog_speed_limits`; None: ``tip_speed``.
        rate_hz: Steps per second while moving.
        sweep_s: Time a held jog takes to sweep a coordinate's whole range (before the cap).
        latch_gap: After a STOP, a held button counts as released after this long without a
            renewal (normally its release is seen at once, see :meth:`release`).
        clock: Monotonic time source.
        on_expired: ``on_expired(reason)`` when a held jog ends because its renewals stopped
            (not on a release): the console core makes that a stop like any other.
    """

    def __init__(self, store: StateStore, *, allowed: Callable[[int], bool] = lambda _: True,
                 heard: Callable[[int], float | None] | None = None, expiry: float = 0.3,
                 tip_speed: float = 0.25, jog_speed: float | None = None,
                 rate_hz: float = 50.0, sweep_s: float = 4.0, latch_gap: float = 2.0,
                 clock: Callable[[], float] = time.monotonic,
                 on_expired: Callable[[str], None] | None = None) -> None:
        if expiry <= 0 or tip_speed <= 0 or rate_hz <= 0 or sweep_s <= 0:
            raise ValueError("expiry, tip_speed, rate_hz and sweep_s must be > 0")
        self.store = store
        self.model = store.model
        self.allowed = allowed
        self.heard = heard
        self.expiry = expiry
        self.tip_speed = tip_speed
        self.period = 1.0 / rate_hz
        self.sweep_s = sweep_s
        self.latch_gap = latch_gap
        self._clock = clock
        self.on_expired = on_expired
        self._cond = threading.Condition()
        self._jog_speed = tip_speed
        if jog_speed is not None:
            self.set_jog_speed(jog_speed)
        self._hold: _Hold | None = None
        self._move: _Move | None = None
        self._latched: dict[tuple[int, str, int], float] = {}
        self._recent: dict[tuple[int, str, int], float] = {}  # last renewal of each held button
        self._last_tick: float | None = None
        self._last_seq = -1
        self.last_note = ""
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # -- the jog speed -----------------------------------------------------------------------

    @property
    def jog_speed(self) -> float:
        """Largest speed of any arm point in held jogs and jog set-points (m/s)."""
        return self._jog_speed

    @property
    def jog_speed_limits(self) -> tuple[float, float]:
        """(slowest, fastest) jog speed an operator may set (m/s): 1 mm/s up to the arm
        model's ``max_jog_speed`` (the extensible arm's tip speed limit), at most the cap."""
        top = self.model.max_jog_speed
        return JOG_SPEED_MIN, self.tip_speed if top is None else min(top, self.tip_speed)

    def set_jog_speed(self, speed: float) -> float:
        """Set the jog speed (m/s; a jog under way goes on at it); returns it.

        Raises:
            ValueError: ``speed`` is not a number within :attr:`jog_speed_limits` (said in
                mm/s); the jog speed stays as it was.
        """
        lo, hi = self.jog_speed_limits
        try:
            value = float(speed)
        except (TypeError, ValueError):
            raise ValueError(f"the jog speed must be a number of mm/s, got {speed!r}") from None
        if not math.isfinite(value) or not lo - 1e-12 <= value <= hi + 1e-12:
            shown = f"{fmt_mm(value, 1)} mm/s" if math.isfinite(value) else repr(speed)
            raise ValueError(f"the jog speed must be between {fmt_mm(lo, 0)} and "
                             f"{fmt_mm(hi, 0)} mm/s, not {shown}")
        with self._cond:
            self._jog_speed = min(max(value, lo), hi)
        return self._jog_speed

    # -- requests (GUI callbacks) -------------------------------------------------------------

    @property
    def active(self) -> bool:
        with self._cond:
            return self._hold is not None or self._move is not None

    def hold(self, client_id: int, coord: Coordinate, direction: int) -> bool:
        """Start or renew a held jog; False if refused (not allowed, or latched by a STOP)."""
        if direction not in (-1, 1):
            raise ValueError(f"direction must be -1 or +1, got {direction}")
        now = self._clock()
        key = (client_id, coord.key, direction)
        with self._cond:
            self._recent[key] = now
            if key in self._latched and now - self._latched[key] < self.latch_gap:
                self._latched[key] = now  # still the press that was stopped: keep it dead
                return False
            self._latched.pop(key, None)
            if not self.allowed(client_id):
                return False
            h = self._hold
            if h is not None and (h.client_id, h.coord.key, h.direction) == key:
                h.renewed = now
            else:
                self._hold = _Hold(client_id, coord, direction, now)
                self._move = None
                self._last_tick = None
            self._cond.notify_all()
            return True

    def release(self, client_id: int, coord: Coordinate | None = None) -> None:
        """End ``client_id``'s held jog (of ``coord`` if given) now: the button was let go."""
        with self._cond:
            h = self._hold
            if h is not None and h.client_id == client_id and (coord is None
                                                                or h.coord.key == coord.key):
                self._hold = None
            for table in (self._latched, self._recent):
                for key in [k for k in table if k[0] == client_id]:
                    del table[key]

    def move_to(self, client_id: int, target: npt.ArrayLike, *, jog: bool = False) -> bool:
        """Move towards ``target`` (validated and clamped) at the capped speed (``jog``: at the
        jog speed, for the Jog panel's sliders, Straighten and Retract); False if refused.

        Raises:
            ValueError: ``target`` is not a valid configuration; nothing changes.
        """
        q, _ = self.model.clamp(self.model.validate(target))
        with self._cond:
            if not self.allowed(client_id):
                return False
            self._move = _Move(client_id, q, self._clock(), jog)
            self._hold = None
            self._last_tick = None
            self._last_seq = self.store.command.seq
            self._cond.notify_all()
            return True

    def target(self) -> Array | None:
        """The set-point being moved to, if any."""
        with self._cond:
            return None if self._move is None else self._move.target.copy()

    def cancel(self, latch: bool = True) -> bool:
        """Stop every jog motion now (STOP, lost lease); returns whether one was running.

        Always commands the current configuration once more, with source ``"stop"``.

        With ``latch`` a hold that is still being renewed stays stopped until released.
        """
        with self._cond:
            was = self._hold is not None or self._move is not None
            now = self._clock()
            if latch:  # also buttons between two (late) renewals: their hold just expired
                for key, t in list(self._recent.items()):
                    if now - t < self.latch_gap:
                        self._latched[key] = now
                    else:
                        del self._recent[key]
            self._hold = None
            self._move = None
            # Always end with a command to stay where it is (panels re-sync their widgets to it,
            # a bridge sees the stop), even when a hold had just expired between renewals.
            self._last_seq = self.store.edit(lambda q: q, STOP_SOURCE).seq
            self._cond.notify_all()
            return was

    # -- motion -----------------------------------------------------------------------------

    def tick(self) -> ArmState | None:
        """One step of the current motion; returns the new command or None (nothing moved).

        A held jog whose renewals stopped ends here and is reported to ``on_expired``."""
        expired = ""
        state = self._tick(self._clock())
        if isinstance(state, str):
            expired, state = state, None
        if expired and self.on_expired is not None:
            self.on_expired(expired)
        return state

    def _tick(self, now: float) -> ArmState | str | None:
        """:meth:`tick` under the lock; a string: the held jog expired (why)."""
        with self._cond:
            h, m = self._hold, self._move
            if h is not None and now - h.renewed > self.expiry and self.allowed(h.client_id):
                self._hold = None
                self._last_tick = None
                return (f"hold-to-run expired: no renewal of the {h.coord.key} jog for "
                        f"{now - h.renewed:.2f} s")
            if h is not None and not self.allowed(h.client_id):
                self._hold = h = None
            if m is not None and (not self.allowed(m.client_id)
                                  or self.store.command.seq != self._last_seq):
                self._move = m = None  # lease gone, or someone else commanded the arm
            if h is None and m is None:
                self._last_tick = None
                return None
            if h is None and m is not None and not self._heard_recently(m, now):
                self._last_tick = None  # hold here; the next answer resumes from rest
                return None
            dt = self.period if self._last_tick is None else min(now - self._last_tick,
                                                                 2 * self.period)
            self._last_tick = now
            jogging = h is not None or (m is not None and m.jog)
            max_disp = min(self.tip_speed, self._jog_speed if jogging else self.tip_speed) * dt
            done = False

            def step(q: Array) -> tuple[Array, str | None]:
                nonlocal done
                if h is not None:
                    c = h.coord
                    rate = (c.hi - c.lo) / self.sweep_s
                    goal, note = self.model.set_coordinate(
                        q, c, float(q[c.index]) + h.direction * rate * dt)
                else:
                    assert m is not None  # a hold or a move: both None returned above
                    goal, note = m.target, None
                new = limit_step(self.model, q, goal, max_disp)
                done = m is not None and bool(np.allclose(new, goal, atol=1e-12, rtol=0))
                return new, note

            state = self.store.edit(step, HOLD_SOURCE if h is not None else MOVE_SOURCE)
            self._last_seq = state.seq
            self.last_note = state.notes[0] if state.notes else ""
            if done:
                self._move = None
            return state

    def _heard_recently(self, m: _Move, now: float) -> bool:
        """Whether the client of set-point move ``m`` gave a sign of life within ``expiry``."""
        if self.heard is None:
            return True
        last = self.heard(m.client_id)
        latest = m.requested if last is None else max(m.requested, last)
        return now - latest < self.expiry

    def start(self) -> None:
        if self._thread is None or not self._thread.is_alive():
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="console-jog", daemon=True)
            self._thread.start()

    def stop(self, timeout: float = 2.0) -> None:
        self._stop.set()
        with self._cond:
            self._cond.notify_all()
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None

    def _run(self) -> None:
        next_t = time.perf_counter()
        while not self._stop.is_set():
            with self._cond:
                if self._hold is None and self._move is None:
                    self._cond.wait(0.5)
                    next_t = time.perf_counter()
                    continue
            self.tick()
            next_t += self.period
            delay = next_t - time.perf_counter()
            if delay > 0:
                self._stop.wait(delay)
            else:  # overrun: skip, never catch up
                next_t = time.perf_counter()
