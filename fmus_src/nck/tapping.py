"""Tapping G84/G74: the M29 rigid-tapping mode, the tapping feed (pitch) and the synchronised rigid stroke.

FANUC 0i-MF / 31i-B semantics (operator's manual "Tapping cycle (G84)", "Left-handed tapping cycle (G74)",
"Rigid tapping"); the moves of one hole are in :mod:`.cycles`.

Conventions
-----------
* The feed must match the thread: under G94 F (mm/min) = pitch x S (rev/min), so pitch = F / S; under G95
  F is the pitch (mm/rev). :func:`tap_feed` returns the Z feed and the pitch; S > 0 is required.
* Conventional tapping needs the spindle turning in the tapping direction: M3 for G84, M4 for G74 (FANUC
  runs the tap with the spindle the program started; the opposite direction would strip the thread). The
  control reverses the spindle at the bottom and again at R.
* Rigid tapping: ``M29 S..`` in a block before G84/G74 (or in the G84/G74 block), or every G84/G74 when
  :attr:`.cycles.CycleMachine.rigid_always` is set (FANUC No. 5200#0). M29 stops the spindle (the twin emits
  a :class:`SpindleStop` and a zero-direction :class:`SpindleSpeed` carrying S, so G95 feeds and spindle
  overrides see the tapping speed) and puts it under position control. It is executed before the block's
  S word and spindle codes. The mode ends with the canned
  cycle (G80 or a G0-G3 code); M29 followed by G80/G0-G3 or another canned cycle before any G84/G74 is an
  error naming the line (FANUC alarm PS0203 style). M29 with M3/M4/M5/M19 in one block is an error.
* A rigid stroke (:func:`rigid_tap_stroke`): the spindle and Z start from rest, accelerate together with the
  spindle acceleration ``a = min(spindle_ramp, spindle_max_speed / rigid_tapping_time_constant)`` (FANUC
  No. 5261: the linear acc/dec time constant to the maximum rigid-tapping speed, which the twin takes as the
  spindle's maximum speed, No. 5241; the acceleration is the same for every S, as FANUC scales the time
  constant by S / Smax), run at S (Z at pitch x S), and decelerate to rest at the end of the stroke. The
  stroke of length D at the Z feed v takes ``D / v + v / a_z`` (``a_z = a x pitch``) or, when it never
  reaches v, ``2 sqrt(D / a_z)``. Both axes stop at the bottom, the dwell P runs, and the spindle reverses
  from rest: that reversal is real cycle time. The twin's ``spindle_ref`` and ``spindle_speed`` are the
  synchronised speed (signed: + CW, - CCW), so the reversal shows as a sign change.

Simplified: the spindle follows its position command exactly (no position-loop lag, no synchronisation
error), the acc/dec is linear (no bell-shaped rigid-tapping acc/dec, No. 5261 + No. 5271), the retract runs
at the same S (no retract override, No. 5211), and Z does not pass the cutting acc/dec after interpolation
(FANUC replaces it by the rigid-tapping one). Gear ranges (No. 5261-5264 per gear) are one value.
"""
from __future__ import annotations

import math

import numpy as np

from .blocks import Block, SpindleSpeed, SpindleStop, Vec3
from .codes import MWords, ValueWords
from .errors import ErrorFactory
from .interpolator import Segment
from .modal import ModalState

#: Rigid-tapping mode of :attr:`ModalState.rigid`: off, M29 given (waiting for G84/G74), in a tapping cycle.
RIGID_OFF, RIGID_PENDING, RIGID_ACTIVE = 0, 1, 2


def rigid_tapping_word(st: ModalState, ms: MWords, vals: ValueWords, line: int, err: ErrorFactory,
                       out: list[Block]) -> None:
    """M29 of a block: stop the spindle and enter rigid-tapping mode (see the module docstring).

    Parameters
    ----------
    st : ModalState
        Modal state (``rigid``, ``direction`` change).
    ms : MWords
        The block's M words.
    vals : ValueWords
        The block's words (the S word was already read).
    line : int
        1-based source line.
    err : ErrorFactory
        Builds the error for this block.
    out : list of Block
        The program's blocks so far.
    """
    if "rigid tapping" not in ms:
        return
    if "spindle" in ms:
        other = ms["spindle"][1]
        raise err("M" + other.text, f"M29 and M{other.text} in one block",
                  "M29 S<rpm> alone before G84/G74 (M29 stops the spindle and puts it under position control)")
    if not st.speed > 0.0:
        raise err("M29", "rigid tapping M29 without a spindle speed S", "M29 S<rpm> with S > 0")
    st.rigid = RIGID_PENDING
    st.direction = 0
    out.append(SpindleStop(line))
    if "S" not in vals:  # an S word in the block gives this command (zero direction) itself
        out.append(SpindleSpeed(line, st.speed, 0, st.speed_line))  # the tapping speed, spindle still stopped


def end_cycle_mode(st: ModalState, word: str, err: ErrorFactory) -> None:
    """G80 or a G0-G3 code ends the canned cycle and the rigid-tapping mode (M29 must be used first).

    Parameters
    ----------
    st : ModalState
    word : str
        The code ending the mode (``"G80"``), for the message.
    err : ErrorFactory
    """
    if st.rigid == RIGID_PENDING:
        raise err(word, f"{word} after M29 before any G84/G74 (FANUC alarm PS0203 style)",
                  "M29 S<rpm> immediately before the G84/G74 tapping block")
    st.cycle = None
    st.rigid = RIGID_OFF


def start_tapping(st: ModalState, code: int, gname: str, vals: ValueWords, line: int, err: ErrorFactory,
                  rigid_always: bool, out: list[Block]) -> bool:
    """Checks of a G84/G74 hole; returns whether it is rigid tapping (may stop the spindle: rigid always).

    Parameters
    ----------
    st : ModalState
    code : int
        84 or 74.
    gname : str
        ``"G84"``/``"G74"`` for messages.
    vals : ValueWords
        The block's words.
    line : int
    err : ErrorFactory
    rigid_always : bool
        FANUC No. 5200#0: G84/G74 are rigid tapping without M29.
    out : list of Block
    """
    if st.rigid == RIGID_OFF and rigid_always:
        st.rigid = RIGID_ACTIVE
        if st.direction != 0:
            out.append(SpindleStop(line))  # position control from rest
            st.direction = 0
    if st.rigid != RIGID_OFF:
        st.rigid = RIGID_ACTIVE
        return True
    want = 1 if code == 84 else -1
    if st.direction != want:
        now = {1: "M3 (clockwise)", -1: "M4 (counter-clockwise)", 0: "stopped"}[st.direction]
        raise err(gname, f"{gname} with the spindle {now}: {gname} taps with the spindle turning "
                  f"{'clockwise (M3)' if want == 1 else 'counter-clockwise (M4)'}",
                  f"{'M3' if want == 1 else 'M4'} S<rpm> before {gname}, or M29 S<rpm> for rigid tapping")
    return False


def tap_feed(st: ModalState, err: ErrorFactory, gname: str) -> tuple[float, float, float]:
    """Z feed (m/s), pitch (m/rev) and feed per revolution (m/rev, 0.0 under G94) of a tapping hole.

    Raises the error of ``err`` when F is missing or in the other feed mode, or S is 0.
    """
    if st.feed is None:
        raise err(gname, f"tapping cycle {gname} with no feed rate (F was never set)",
                  "F = pitch x S (G94, mm/min) or F = pitch (G95, mm/rev) on this or an earlier block")
    if st.feed_per_rev != st.per_rev:
        mode = "G95" if st.per_rev else "G94"
        raise err(gname, f"tapping cycle {gname} in {mode} but the modal F (line {st.feed_line}) was given in the "
                  "other feed mode", f"an F word after switching to {mode}")
    if not st.speed > 0.0:
        raise err(gname, f"tapping cycle {gname} with spindle speed S0", "S > 0: the pitch is F / S (G94) or F (G95)")
    rev_per_s = st.speed / (2.0 * math.pi)
    if st.per_rev:
        return st.feed * rev_per_s, st.feed, st.feed
    return st.feed, st.feed / rev_per_s, 0.0


def rigid_tap_accel(spindle_ramp: float, spindle_max_speed: float, time_constant: float) -> float:
    """Spindle acceleration of rigid tapping (rad/s2): ``min(ramp, max speed / time constant)``.

    Parameters
    ----------
    spindle_ramp : float
        Spindle acceleration of the drive (rad/s2).
    spindle_max_speed : float
        Maximum spindle speed (rad/s), taken as FANUC's maximum rigid-tapping speed (No. 5241).
    time_constant : float
        Rigid-tapping linear acc/dec time constant to that speed (s, FANUC No. 5261); 0: the ramp alone.
    """
    if time_constant <= 0.0:
        return spindle_ramp
    return min(spindle_ramp, spindle_max_speed / time_constant)


def rigid_tap_stroke(start: Vec3, end: Vec3, feed: float, pitch: float, direction: int, spindle_accel: float,
                     period: float) -> tuple[Segment, np.ndarray]:
    """Samples of one rigid-tapping stroke, Z synchronised with the spindle, from rest to rest.

    Parameters
    ----------
    start, end : Vec3
        Machine positions (m); only Z differs.
    feed : float
        Z feed at full speed (m/s), > 0.
    pitch : float
        Thread pitch (m/rev), > 0.
    direction : int
        Spindle direction during the stroke, +1 CW, -1 CCW.
    spindle_accel : float
        Spindle acceleration (rad/s2), > 0 (:func:`rigid_tap_accel`).
    period : float
        Interpolation period Ts (s).

    Returns
    -------
    segment : Segment
        Positions and Z speed at ``k Ts``, ``k = 0..n``; the last sample is exactly ``end``; ``duration`` =
        ``D / v + v / a_z`` (trapezoid) or ``2 sqrt(D / a_z)`` (triangle), ``a_z = spindle_accel x pitch / 2 pi``.
    spindle : ndarray (n + 1,)
        Signed spindle speed (rad/s): ``direction x 2 pi x Z speed / pitch``.
    """
    p0 = np.asarray(start, dtype=float)
    p1 = np.asarray(end, dtype=float)
    dist = float(np.linalg.norm(p1 - p0))
    a = spindle_accel * pitch / (2.0 * math.pi)  # Z acceleration, m/s2
    v = feed
    t_acc = v / a
    if dist >= v * t_acc:
        duration = dist / v + t_acc
    else:
        v = math.sqrt(dist * a)
        t_acc = v / a
        duration = 2.0 * t_acc
    n = max(int(math.ceil(duration / period - 1e-9)), 0)
    t = np.minimum(np.arange(n + 1) * period, duration)
    t_dec = duration - t_acc  # deceleration starts
    speed = np.minimum(np.minimum(a * t, v), a * (duration - t))
    speed = np.maximum(speed, 0.0)
    s = np.where(t <= t_acc, 0.5 * a * t * t,
                 np.where(t <= t_dec, 0.5 * a * t_acc * t_acc + v * (t - t_acc),
                          dist - 0.5 * a * (duration - t) ** 2))
    frac = np.clip(s / dist, 0.0, 1.0) if dist > 0.0 else np.ones_like(s)
    position = p0 + frac[:, None] * (p1 - p0)
    position[-1] = p1
    speed[-1] = 0.0
    spindle = direction * speed * 2.0 * math.pi / pitch
    return Segment(position, speed, np.array([0.0]), duration), spindle


__all__ = [
    "RIGID_ACTIVE", "RIGID_OFF", "RIGID_PENDING", "end_cycle_mode", "rigid_tap_accel", "rigid_tap_stroke",
    "rigid_tapping_word", "start_tapping", "tap_feed",
]
