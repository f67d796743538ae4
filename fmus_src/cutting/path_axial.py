"""The axial chip (end edges, :mod:`.axial`) in the path mode: read from the engagement table's stations.

The reference pass (:func:`.table.build_engagement_table`) evaluates :func:`.axial.axial_cut` at every station
``i`` for the move from station ``i - 1``, on the same Z-map and recent path the periphery's intervals come
from, and stores it per unit of descent: ``axial_area[i] = sum d dA / dz`` [m2] and
``axial_span[i] = sum d dA / r / dz`` [m] (``dz`` the stations' height difference; 0 where the path does
not move down). For a plunge into solid these are ``pi R^2`` and ``2 pi R``.

A member that moves down by ``dz`` [m] in a step of ``h`` [s] and ends at arc length ``s`` then gets, from the
station ``ceil(s / ds)`` (the interval it has just travelled): removal ``area dz / h``, torque
``Kt removal / omega`` and thrust ``ka Kt span dz / (h omega)``, as the Z-map mode's end edges. The member's
own descent is used, the material under the end disc is the reference pass's.
"""
from __future__ import annotations

import math

import numpy as np

from ..jit import njit
from ..jit_cache import guard_cache
from . import kernel, path_kernel
from .kernel import OMEGA_FLOOR, OMEGA_STOPPED
from .path_kernel import OUT_MRR, OUT_POWER, OUT_TORQUE, PAR_KT, ST_S, ST_Z


@njit
def path_axial(out: np.ndarray, fz: np.ndarray, st: np.ndarray, z_old: np.ndarray, inp: np.ndarray,
               par: np.ndarray, ka: np.ndarray, h: float, area: np.ndarray, span: np.ndarray, ds: float) -> None:
    """Add the end edges' torque, power and removal to a path-mode step's outputs; write the thrust ``fz``.

    Parameters
    ----------
    out : ndarray, shape (12, B)
        The step's outputs (rows ``path_kernel.OUT_*``), updated in place; a member whose removal rate is
        not finite (blanked: failed or lost) is left alone and gets ``fz`` NaN.
    fz : ndarray, shape (B,)
        Z force on the workpiece (minus the thrust), N, written.
    st : ndarray, shape (ST_ROWS, B)
        Kernel state after the step (tip height ``ST_Z`` m, arc length ``ST_S`` m).
    z_old : ndarray, shape (B,)
        Tip height at the step's start, m.
    inp : ndarray, shape (4, B)
        The kernel's inputs (spindle speed in row 3, rad/s).
    par : ndarray, shape (5, B)
        The kernel's parameters (``Kt`` N/m2 in row ``PAR_KT``, wear included).
    ka : ndarray, shape (B,)
        End-edge thrust / tangential force ratio, 1.
    h : float
        Step, s.
    area, span : ndarray, shape (S,)
        The table's ``axial_area`` [m2] and ``axial_span`` [m] per station.
    ds : float
        Station spacing, m.
    """
    n_st = area.shape[0]
    for m in range(out.shape[1]):
        if not math.isfinite(out[OUT_MRR, m]):
            fz[m] = math.nan
            continue
        fz[m] = 0.0
        dz = z_old[m] - st[ST_Z, m]
        if not (dz > 0.0 and n_st > 0):
            continue
        i = int(math.ceil(st[ST_S, m] / ds - 1e-9))
        i = min(max(i, 0), n_st - 1)
        if not area[i] > 0.0:
            continue
        om = max(inp[3, m], 0.0)
        w = max(om, OMEGA_FLOOR)
        kt = par[PAR_KT, m]
        mrr = area[i] * dz / h
        torque = out[OUT_TORQUE, m] + kt * mrr / w
        out[OUT_TORQUE, m] = torque
        out[OUT_POWER, m] = torque * om
        out[OUT_MRR, m] = out[OUT_MRR, m] + mrr
        if om < OMEGA_STOPPED:
            # a plunge with the spindle stopped (a crash the path mode does not check): no finite thrust exists;
            # none is passed on to the Z drive, the periphery's check fails the member (kernel.stalled_cut)
            continue
        fz[m] = -(ka[m] * kt * span[i] * dz / (h * w))


# the cached kernel holds constants of kernel and path_kernel: recompile on change
guard_cache(path_axial, kernel, path_kernel)
