"""Is a Stribeck fit's residual explained by the data's own noise? (chi-square test of the friction fit).

Each Stribeck point is the mean force of a constant-velocity plateau; its standard error follows from the
scatter of the force within that plateau, ``s / sqrt(n)`` (:class:`.segments.Segment` ``force_std``,
``samples``), at least ``RELATIVE_FLOOR`` of the force. If the friction follows the Stribeck law, the
normalised residuals ``r_i / (s_i / sqrt(n_i))`` of the best Stribeck curve are standard normal and their
sum of squares follows a chi-square law with ``points - 4`` degrees of freedom (four parameters fitted).
A sum above its ``1 - MISFIT_PROBABILITY`` quantile means the law does not describe the data (a bump the
Stribeck curve cannot follow, a mixed-up log), not that the data are noisy: the fit then carries a note
naming the speeds where it misfits.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from scipy.stats import chi2

from .segments import Segment
from .stribeck import StribeckFit

#: Floor of a plateau mean's standard error relative to its force: a noise-free log (a twin run) has plateaus
#: that scatter by microampere-level loop ripple, and misfits by hundredths of a newton (fit tolerance,
#: plateau-mean bias) are not a different friction law.
RELATIVE_FLOOR = 1e-4
#: False-alarm probability of the misfit test per axis and direction (a Stribeck log is flagged this rarely).
MISFIT_PROBABILITY = 1e-3


def stribeck_misfit(segments: Sequence[Segment], fit: StribeckFit, label: str) -> str | None:
    """A warning when the fit's residual is far above what the plateaus' scatter explains, else None.

    Parameters
    ----------
    segments : sequence of Segment
        The plateaus of one axis and direction that were fitted (force signed, velocity in m/s).
    fit : StribeckFit
        Their best Stribeck fit (magnitudes; the default method's, see :func:`.stribeck.fit_stribeck`).
    label : str
        ``"file: axis x positive"``, starts the note.

    Returns
    -------
    str or None
        ``"<label>: the Stribeck fit misfits ..."`` with the chi-square, its bound and the speeds [mm/min]
        whose normalised residual exceeds the ``1 - MISFIT_PROBABILITY`` quantile of chi-square(1); None
        when the residual is within the bound or there are no more points than parameters.
    """
    dof = len(segments) - 4
    if dof < 1:
        return None
    speed = np.array([abs(s.velocity) for s in segments])
    force = np.array([abs(s.force) for s in segments])
    sem = np.array([s.force_std / math.sqrt(s.samples) if s.samples > 1 else 0.0 for s in segments])
    if not np.any(sem > 0.0):
        sem = RELATIVE_FLOOR * force
    else:
        sem = np.where(sem > 0.0, sem, float(np.median(sem[sem > 0.0])))  # a plateau without scatter: the typical one
    sem = np.maximum(sem, RELATIVE_FLOOR * force)
    z = (force - fit.force(speed)) / sem
    stat = float(z @ z)
    bound = float(chi2.ppf(1.0 - MISFIT_PROBABILITY, dof))
    if stat <= bound:
        return None
    point = float(np.sqrt(chi2.ppf(1.0 - MISFIT_PROBABILITY, 1)))
    worst = np.argsort(-np.abs(z))
    bad = [int(i) for i in worst if abs(z[i]) > point] or [int(worst[0])]
    where = ", ".join(f"{speed[i] * 6e4:.4g} mm/min ({force[i] - fit.force(speed[i]):+.3g} N, "
                      f"{z[i]:+.1f} sigma)" for i in sorted(bad, key=lambda i: speed[i]))
    return (f"{label}: the Stribeck fit misfits: chi-square {stat:.3g} of the {len(segments)} points against their "
            f"plateau scatter, above its {100 * (1 - MISFIT_PROBABILITY):g} % bound {bound:.3g} "
            f"({dof} degrees of freedom); the friction does not follow the Stribeck law at {where}. "
            "Treat these parameters with care (check the log, or a friction law other than Stribeck)")
