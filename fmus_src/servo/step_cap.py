"""The cap of a feed drive's internal step set by its Stribeck friction (numpy only, no compiled kernels).

A module of its own so that reading a machine file (:mod:`orchestrator.machine` checks the cap a file implies)
does not import numba through :mod:`fmus_src.servo.drive`.
"""
from __future__ import annotations

import math

import numpy as np

from .friction import StribeckParameters

#: The internal step is further capped so that (Stribeck growth rate) x step <= this value, where the
#: growth rate is max(0, (Fs - Fc) / vs - mu_v) / Ms, the largest positive eigenvalue of the sliding
#: dynamics. Inactive for Table 1 values (cap >= 480 us); it keeps a GA's extreme trial parameters
#: (vs = 0.1 mm/s, Fs - Fc = 700 N, 600 kg: cap ~ 21 us) about as accurate as the paper's, at the
#: price of more substeps for that member only.
STRIBECK_STEP_FACTOR = 0.25


def stribeck_step_cap(friction: StribeckParameters, mass: np.ndarray) -> np.ndarray:
    """Largest internal step [s] of each member with (Stribeck growth rate) x step <= ``STRIBECK_STEP_FACTOR``.

    Parameters
    ----------
    friction : StribeckParameters
        Both branches, shape (B,).
    mass : ndarray, shape (B,)
        Moving mass [kg].

    Returns
    -------
    ndarray, shape (B,)
        The cap [s]; ``inf`` for a member without a growing Stribeck mode.
    """
    worst = np.maximum(
        np.maximum(0.0, (friction.static_pos - friction.coulomb_pos) / friction.stribeck_velocity_pos
                   - friction.viscous_pos) / mass,
        np.maximum(0.0, (friction.static_neg - friction.coulomb_neg) / friction.stribeck_velocity_neg
                   - friction.viscous_neg) / mass,
    )
    with np.errstate(divide="ignore"):
        return np.where(worst == 0.0, math.inf, STRIBECK_STEP_FACTOR / worst)
