"""Whether the twin's Z drive can carry a thrust at all: a bound from its run without cutting.

The twin's only Z force of the cutting load is the end edges' thrust (:mod:`fmus_src.cutting.axial`,
:mod:`fmus_src.cutting.path_axial`): ``ka Kt span dz / (h omega)``, nonzero only while the tool tip moves
down (``dz > 0``) with its end disc over material. A flat end mill's side cut or slot at a fixed height
gives none. ``span`` (the integral of ``dA / r`` over the material under the end disc) is at most ``2 pi R``
(a plunge into solid), and the material lies within the stock block: the span over the block's footprint
bounds it. So over the samples of the twin's run without cutting where the tip descends inside the block's
height with the disc over its footprint, ``ka Kt span v_down / max(omega, OMEGA_FLOOR)`` bounds the thrust;
elsewhere it is zero. The Z slide's motion does not depend on the x and y cutting forces, so the run
without cutting moves Z as the run with cutting does, up to the thrust itself and the spindle's droop under
load (a full plunge at F300 S6000: 51.66 N from the run without cutting, 51.91 N in the run with it).

Used by :func:`.prepare.prepare` for a dynamometer without ``fz_N``: the twin's run with cutting for the
thrust is skipped when the bound stays below a tenth of :data:`.prepare.NEGLIGIBLE_LOAD_N` (a Z load it
would have dropped anyway).
"""
from __future__ import annotations

import math

import numpy as np

from fmus_src.cutting.axial import AXIAL_RATIO_DEFAULT
from fmus_src.cutting.kernel import OMEGA_FLOOR

from ..case import Case
from ..machine import Machine
from ..recording import Recording
from ..twin import cutting_effect_parameters


def thrust_bound(case: Case, machine: Machine, nc: Recording) -> float:
    """Upper bound of the twin's end-edge thrust over its run ``nc`` without cutting, N (see module docstring).

    Parameters
    ----------
    case : Case
        Stock [mm], tool and material.
    machine : Machine
        Material coefficients ``kt`` [N/m2] and ``ka`` [1].
    nc : Recording
        The twin's run without cutting (:func:`.prepare.twin_commands`): ``z_mm``, ``x_mm``, ``y_mm`` (tool
        tip, work coordinates) and ``spindle_rpm``.

    Returns
    -------
    float
        0 without a stock or when the tip never descends over the stock block; ``inf`` when the machine
        file has ``[cutting.effects]`` (which may raise ``Kt`` during the run: no bound is claimed).
    """
    if case.stock is None:
        return 0.0
    if cutting_effect_parameters(machine):
        return math.inf
    mat = machine.si(f"material.{case.material}")
    kt = float(mat["kt"])
    ka = float(mat["ka"]) if "ka" in mat else AXIAL_RATIO_DEFAULT
    radius = 0.5 * case.tool.diameter_mm * 1e-3
    t = np.asarray(nc.t, float)
    p = {a: np.asarray(nc[f"{a}_mm"], float) * 1e-3 for a in "xyz"}
    lo = np.asarray(case.stock.min_mm, float) * 1e-3
    hi = np.asarray(case.stock.max_mm, float) * 1e-3
    dt = np.diff(t)
    down = np.where(dt > 0, (p["z"][:-1] - p["z"][1:]) / np.where(dt > 0, dt, 1.0), 0.0)
    # the step's end (where the component evaluates its descent), conservatively also its start
    zs = np.minimum(p["z"][:-1], p["z"][1:])
    gap = [np.maximum(np.maximum(lo[i] - np.minimum(p[a][:-1], p[a][1:]),
                                 np.maximum(p[a][:-1], p[a][1:]) - hi[i]), 0.0) for i, a in enumerate("xy")]
    over = np.hypot(gap[0], gap[1]) < radius
    inside = over & (zs < hi[2]) & (np.maximum(p["z"][:-1], p["z"][1:]) > lo[2]) & (down > 0.0)
    if not inside.any():
        return 0.0
    k = np.flatnonzero(inside)
    omega = np.asarray(nc["spindle_rpm"], float) * 2.0 * math.pi / 60.0
    w = np.maximum(np.minimum(np.abs(omega[k]), np.abs(omega[k + 1])), OMEGA_FLOOR)
    span = np.maximum(_span_over_block(p["x"][k], p["y"][k], radius, lo, hi),
                      _span_over_block(p["x"][k + 1], p["y"][k + 1], radius, lo, hi))
    return float(np.max(ka * kt * span * down[k] / w))


def _span_over_block(x: np.ndarray, y: np.ndarray, radius: float, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """``integral dA / r`` over the part of the end disc (centre ``x``, ``y`` [m]) above the block's footprint, m.

    In polar coordinates ``dA / r = dr dtheta``: the measure of the (r, theta) cells whose centre lies over the
    block, plus one cell's width around the block's edges (an upper bound; 2 pi R over the whole block).
    """
    nr, nt = SPAN_CELLS
    dr, dt = radius / nr, 2.0 * math.pi / nt
    r = (np.arange(nr) + 0.5) * dr
    th = (np.arange(nt) + 0.5) * dt
    ox = (r[:, None] * np.cos(th)[None, :]).ravel()
    oy = (r[:, None] * np.sin(th)[None, :]).ravel()
    pad = max(dr, radius * dt)     # a cell's largest extent: a cell that touches the block counts
    out = np.empty(x.size)
    for i0 in range(0, x.size, 256):
        px = x[i0:i0 + 256, None] + ox[None, :]
        py = y[i0:i0 + 256, None] + oy[None, :]
        over = (px > lo[0] - pad) & (px < hi[0] + pad) & (py > lo[1] - pad) & (py < hi[1] + pad)
        out[i0:i0 + 256] = over.sum(axis=1) * dr * dt
    return out


#: Radial and angular cells of the end disc in :func:`_span_over_block`.
SPAN_CELLS = (24, 96)
