"""Current of a feed drive that sticks under a measured load: the held current is not predictable.

A drive at rest holds the current its PI velocity loop has wound up: while
the table sticks, the integrator ramps at ``kp ki e`` with the position error
``e`` left by the last slip, so the held current is ``i0 + kp (kv + ki (t -
t0)) e``. Near breakaway (the integrator holds the axis at static friction,
creeping in nanometre slips) any load change moves the axis by a fraction of
a micrometre and so sets ``e``. A replay loaded with a *measured* cutting
force (noise of about a newton per sample, tooth-frequency content sampled
a few times per tooth) cannot follow those slips: a 1 N load noise changes
``e`` by tens of nanometres, far below the encoder resolution, which is
0.1-0.3 A of held current after half a second (``kp ki`` = 6e6 A/m/s on the
default axes). Both the truth and the twin stick exactly (the same static
friction); they only disagree about a state no recording resolves.

So for every stretch in which the baseline replay of a loaded axis holds
its position (:func:`stuck_stretches`: at rest, or creeping by stick-slip
slower than 3 mm/min, split where it changes between the two, since the
machine's slips need not be the replay's), the current rows are left out of
the regression (:func:`leave_out_held_current`): neither the selection nor the
refit nor the unexplained-residual search sees them, and the minimum gains
are still counted per sample including them. (An offset and a ramp per hold
fitted as artefacts, as before, left the part of an effect's column inside
the holds unabsorbed: a 1 ms servo delay on a mostly held axis then got a
coefficient of nearly 0.) Axes without a measured load are untouched: there
the replay reproduces the held current exactly.

The held-current difference does not end with the hold: it is a difference
of the velocity loop's integrator, and when the axis breaks away into its
next move the loop starts from it. An integrator offset ``δ`` adds ``δ`` to
the current command, which is the same as a force ``-Kf δ`` on the table
(``Kf = 2π kt / lead``) with the loop answering it. So each hold end gets an
artefact ``δ (1 + Δi(t) / δ)`` in the current and ``Δe(t)`` in the following
error, where ``Δi, Δe`` are the replay's answer to that force step
(:func:`breakaway_responses`, one batched replay, a member per hold). The
answer decays as the loop winds the integrator back (tens of ms here).
Without it, the 0.6 A transient at the start of a loaded axis's move read
as a Coulomb friction change.
"""
from __future__ import annotations

import math
from typing import Callable, Mapping

import numpy as np

from ..machine import Machine
from ..twin import drive_parameters
from .columns import AxisColumns
from .model import Simulated

#: ``replay(disturbance, batch)``: the baseline model replayed under per-member disturbances
#: (axis -> ``f(t)`` [N], shape (n,) or (n, B)).
Replay = Callable[[Mapping[str, Callable[[np.ndarray], np.ndarray]], int], Simulated]

#: A stuck stretch shorter than this gets no artefact (its held current cannot drift far), s.
MIN_STUCK_S = 0.02
#: Motor motion between two samples below this counts as stuck, m (the twin's stick is exact).
STUCK_MOTION_M = 1e-10
#: A motor slower than this between two samples creeps (stick-slip under a load), m/s: 3 mm/min, far
#: below any programmed feed, far above the nanometre slips of a loaded axis holding a position.
CREEP_SPEED_M_S = 5e-5
#: Integrator offset whose answer is replayed after a hold, A (the artefact is linear in it).
BREAKAWAY_PROBE_A = 0.1


def stuck_stretches(t: np.ndarray, motor: np.ndarray, min_s: float = MIN_STUCK_S) -> list[tuple[int, int]]:
    """Index ranges ``[i0, i1]`` (inclusive, disjoint) over which the motor holds its current.

    A *hold* is a span of at least ``min_s`` in which the motor moves slower than
    :data:`CREEP_SPEED_M_S` between samples: at rest, or creeping by stick-slip under a load (slips of
    tens to hundreds of nanometres, each resetting the integrator the loop then winds up again). It is
    split into its stretches of exact rest (:data:`STUCK_MOTION_M`, at least ``min_s`` long) and the
    creep between them, because a slip that the replay makes and the machine does not (or the other way
    round) changes the held current there: each piece is returned.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Sample times, s.
    motor : ndarray, shape (n,)
        Replayed motor position, m.
    min_s : float
        Shortest hold, s.

    Returns
    -------
    list of (int, int)
    """
    step = np.abs(np.diff(motor))
    still = step < STUCK_MOTION_M
    slow = still | (step < CREEP_SPEED_M_S * np.diff(t))
    out: list[tuple[int, int]] = []
    for i, j in _runs(slow):
        # samples i .. j hold
        if t[j] - t[i] < min_s:
            continue
        first = i
        for a, b in _runs(still[i:j]):
            a, b = a + i, b + i
            if t[b] - t[a] < min_s:
                continue          # a pause within the creep, not a rest of its own
            if a > first:
                out.append((first, a - 1))
            out.append((a, b))
            first = b + 1
        if j > first:
            out.append((first, j))
    return out


def _runs(flags: np.ndarray) -> list[tuple[int, int]]:
    """Sample ranges ``[i, j]`` spanned by the maximal runs of true ``flags`` over steps ``i .. j-1``."""
    edges = np.diff(np.concatenate(([0], flags.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist()))


def breakaway_responses(t: np.ndarray, ends: list[tuple[str, int]], machine: Machine,
                        disturbance: Mapping[str, Callable[[np.ndarray], np.ndarray]], replay: Replay
                        ) -> list[tuple[np.ndarray, np.ndarray]]:
    """The replay's answer to an integrator offset of one ampere left at the end of each hold.

    Member 0 of one batched replay is the baseline; member ``k + 1`` carries, after sample ``ends[k]``
    of its axis, the extra force ``-Kf δ`` (:data:`BREAKAWAY_PROBE_A`).

    Parameters
    ----------
    t : ndarray, shape (n,)
        Sample times (the replay's clock), s.
    ends : list of (str, int)
        Axis and last sample of each hold.
    machine : Machine
    disturbance : mapping axis -> callable
        The replay's load, ``f(t)`` [N].
    replay : callable

    Returns
    -------
    list of (ndarray, ndarray), shape (n,) each
        Per hold: the current ``1 + Δi / δ`` [A/A] and the following error ``Δe / δ`` [µm/A], zero up to and
        including the hold's last sample.
    """
    batch = len(ends) + 1
    kf = {}
    for a in {a for a, _ in ends}:
        p = drive_parameters(machine, a)
        kf[a] = float(p["torque_constant"]) * 2.0 * math.pi / float(p["screw_lead"])
    t_end = np.array([t[i] for _, i in ends])

    def stepped(a: str) -> Callable[[np.ndarray], np.ndarray]:
        base = disturbance.get(a)
        on_axis = np.array([e == a for e, _ in ends])

        def load(q: np.ndarray) -> np.ndarray:
            q = np.asarray(q, dtype=float)
            out = np.zeros((q.size, batch))
            if base is not None:
                out[:] = np.asarray(base(q), dtype=float)[:, None]
            after = (q[:, None] > t_end[None, :]) & on_axis[None, :]
            out[:, 1:] -= np.where(after, kf.get(a, 0.0) * BREAKAWAY_PROBE_A, 0.0)
            return out
        return load

    sim = replay({a: stepped(a) for a in set(disturbance) | set(kf)}, batch)
    out = []
    for k, (a, i) in enumerate(ends):
        after = t > t[i]
        di = (sim.current[a][:, k + 1] - sim.current[a][:, 0]) / BREAKAWAY_PROBE_A
        de = (sim.fe[a][:, k + 1] - sim.fe[a][:, 0]) / BREAKAWAY_PROBE_A
        out.append((np.where(after, 1.0 + di, 0.0), np.where(after, de, 0.0)))
    return out


def leave_out_held_current(t: np.ndarray, cols: Mapping[str, AxisColumns], sim: Simulated,
                        disturbance: Mapping[str, Callable[[np.ndarray], np.ndarray]] | None,
                        member: int = 0, machine: Machine | None = None, replay: Replay | None = None
                        ) -> dict[str, int]:
    """Leave out the current rows of the holds of loaded axes, and add their breakaway artefacts, in place.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Sample times (the replay's clock), s.
    cols : mapping axis -> AxisColumns
        The regression columns. The current rows inside the holds leave ``rows_tc`` (and ``y``,
        ``columns`` and ``artefacts`` lose them); ``artefacts`` gains ``"{a} stuck k breakaway A"`` per
        hold end, the loop's answer to the integrator offset the hold leaves (weighted like the rows).
    sim : Simulated
        The replay whose member ``member`` is the baseline (its motor positions define the holds).
    disturbance : mapping axis -> callable, or None
        The load of the replay (``f(t)`` [N]); only axes loaded within a hold are concerned.
    machine : Machine, optional
    replay : callable, optional
        ``replay(disturbance, batch)``: the baseline model under per-member loads. With ``machine``, each
        hold end gets its breakaway artefact (:func:`breakaway_responses`); without, the rows are only
        left out.

    Returns
    -------
    dict axis -> int
        Number of hold pieces left out per axis.
    """
    counts: dict[str, int] = {}
    if not disturbance:
        return counts
    pieces: list[tuple[str, int, int]] = []
    for a, c in cols.items():
        if a not in disturbance or c.rows_tc.size == 0:
            continue
        load = np.asarray(disturbance[a](t), dtype=float)
        for i0, i1 in stuck_stretches(t, sim.motor[a][:, member]):
            if np.any(load[i0:i1 + 1] != 0.0) and int(((c.rows_tc >= i0) & (c.rows_tc <= i1)).sum()) >= 3:
                pieces.append((a, i0, i1))
    # the pieces after which the motor moves on (the end of a hold, not of a rest inside it)
    ends = [k for k, (a, _, i1) in enumerate(pieces) if i1 + 1 < t.size
            and abs(sim.motor[a][i1 + 1, member] - sim.motor[a][i1, member]) >= CREEP_SPEED_M_S * (t[i1 + 1] - t[i1])]
    after = {}
    if ends and replay is not None and machine is not None:
        answers = breakaway_responses(t, [(pieces[k][0], pieces[k][2]) for k in ends], machine, disturbance, replay)
        after = dict(zip(ends, answers))
    for a in {a for a, _, _ in pieces}:
        c = cols[a]
        held = np.zeros(t.size, dtype=bool)
        for b, i0, i1 in pieces:
            if b == a:
                held[i0:i1 + 1] = True
        keep_tc = ~held[c.rows_tc]
        keep = np.concatenate([np.ones(c.rows_fe.size, dtype=bool), keep_tc])
        c.rows_left_out += int((~keep_tc).sum())
        c.rows_tc = c.rows_tc[keep_tc]
        c.y = c.y[keep]
        c.columns = {key: col[keep] for key, col in c.columns.items()}
        c.artefacts = {key: col[keep] for key, col in c.artefacts.items()}
        counts[a] = sum(1 for b, _, _ in pieces if b == a)
    for count, k in enumerate(sorted(after)):
        a = pieces[k][0]
        c = cols[a]
        tc_after, fe_after = after[k]
        col = np.concatenate([fe_after[c.rows_fe] / c.sigma_fe, tc_after[c.rows_tc] / c.sigma_tc])
        c.artefacts[f"{a} stuck {count} breakaway A"] = col
    return counts
