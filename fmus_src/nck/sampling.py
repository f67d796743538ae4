"""Where a fractional sample index falls between the planned interpolator samples (shared by the NC kernel
component and the compiled master loop, so both read the plan identically)."""
from __future__ import annotations

import math

from ..jit import njit_inline


@njit_inline
def sample_position(kf: float, n_samples: int) -> tuple[int, int, float]:
    """Samples around the fractional index ``kf`` of a plan with ``n_samples`` samples per member.

    ``kf`` is clamped to ``[0, n_samples - 1]``; fractions below 1e-9 count as 0 (a
    sample instant read by a step end that rounding put just past it).

    Parameters
    ----------
    kf : float
        Fractional sample index, ``(t - t0) / period`` [1].
    n_samples : int
        Samples per member of the plan.

    Returns
    -------
    k0, k1 : int
        The sample at or before ``kf`` and the next one (``k0`` at the end of the plan).
    frac : float
        Linear interpolation weight of ``k1`` in ``[0, 1)``.
    """
    kf = min(max(kf, 0.0), n_samples - 1.0)
    k0 = int(math.floor(kf + 1e-9))
    frac = kf - k0
    if frac < 1e-9:
        frac = 0.0
    k1 = min(k0 + 1, n_samples - 1)
    return k0, k1, frac
