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
machine's slips need not be the replay's), an offset and a ramp of the
current are fitted
as artefacts with the channel offsets (:func:`add_stuck_artefacts`), and
neither the selection nor the unexplained-residual search sees them. Axes
without a measured load are untouched: there the replay reproduces the
held current exactly.
"""
from __future__ import annotations

from typing import Callable, Mapping

import numpy as np

from .columns import AxisColumns
from .model import Simulated

#: A stuck stretch shorter than this gets no artefact (its held current cannot drift far), s.
MIN_STUCK_S = 0.02
#: Motor motion between two samples below this counts as stuck, m (the twin's stick is exact).
STUCK_MOTION_M = 1e-10
#: A motor slower than this between two samples creeps (stick-slip under a load), m/s: 3 mm/min, far
#: below any programmed feed, far above the nanometre slips of a loaded axis holding a position.
CREEP_SPEED_M_S = 5e-5


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


def add_stuck_artefacts(t: np.ndarray, cols: Mapping[str, AxisColumns], sim: Simulated,
                        disturbance: Mapping[str, Callable[[np.ndarray], np.ndarray]] | None,
                        member: int = 0) -> dict[str, int]:
    """Add held-current offset and ramp artefacts for the stuck stretches of loaded axes, in place.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Sample times (the replay's clock), s.
    cols : mapping axis -> AxisColumns
        The regression columns; ``artefacts`` gains ``"{a} stuck k offset A"`` and
        ``"{a} stuck k ramp A/s"`` (weighted like the current rows).
    sim : Simulated
        The replay whose member ``member`` is the baseline (its motor positions define the stretches).
    disturbance : mapping axis -> callable, or None
        The measured load of the replay (``f(t)`` [N]); only axes loaded within a stretch get artefacts.

    Returns
    -------
    dict axis -> int
        Number of stretches given artefacts per axis.
    """
    counts: dict[str, int] = {}
    if not disturbance:
        return counts
    for a, c in cols.items():
        if a not in disturbance or c.rows_tc.size == 0:
            continue
        load = np.asarray(disturbance[a](t), dtype=float)
        nf, count = c.rows_fe.size, 0
        for i0, i1 in stuck_stretches(t, sim.motor[a][:, member]):
            if not np.any(load[i0:i1 + 1] != 0.0):
                continue
            inside = (c.rows_tc >= i0) & (c.rows_tc <= i1)
            if inside.sum() < 3:
                continue
            tt = t[c.rows_tc]
            mid = 0.5 * (t[i0] + t[i1])
            for name, values in (("offset A", np.ones(tt.size)), ("ramp A/s", tt - mid)):
                col = np.zeros(nf + c.rows_tc.size)
                col[nf:] = np.where(inside, values, 0.0) / c.sigma_tc
                c.artefacts[f"{a} stuck {count} {name}"] = col
            count += 1
        if count:
            counts[a] = count
    return counts
