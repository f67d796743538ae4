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

So for every stretch in which the baseline replay of a loaded axis sticks
(motor position constant), an offset and a ramp of the current are fitted
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


def stuck_stretches(t: np.ndarray, motor: np.ndarray, min_s: float = MIN_STUCK_S) -> list[tuple[int, int]]:
    """Index ranges ``[i0, i1]`` (inclusive) over which the motor position does not change.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Sample times, s.
    motor : ndarray, shape (n,)
        Replayed motor position, m.
    min_s : float
        Shortest stretch returned, s.

    Returns
    -------
    list of (int, int)
    """
    still = np.abs(np.diff(motor)) < STUCK_MOTION_M
    out: list[tuple[int, int]] = []
    i = 0
    n = still.size
    while i < n:
        if not still[i]:
            i += 1
            continue
        j = i
        while j < n and still[j]:
            j += 1
        # samples i .. j are at the same position
        if t[j] - t[i] >= min_s:
            out.append((i, j))
        i = j
    return out


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
