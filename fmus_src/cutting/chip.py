"""Scalar kernels of the cutting-effect terms (numba; plain Python without it).

Used by :mod:`.kernel_effects` (Z-map mode) and :mod:`.path_effects` (path
mode), so both modes share one implementation of the physics of
:mod:`.effects`:

* :func:`positive_chip_integrals` — exact integrals over an angle interval of
  the generalised chip ``h = a sin phi + b cos phi + c`` where it is positive
  (runout offsets, regenerative and deflection terms make ``c != 0`` and move
  the zero crossings of the chip); :func:`envelope_integrals` the same for the
  lowest of several such forms (the surfaces left by the last teeth, at most
  :data:`.effect_model.MAX_PASSES`);
* :func:`add_piece` / :func:`add_piece_point` — mean force, torque and removal
  rate of one tooth (or helix band) over a piece of a substep, with edge forces;
* :func:`edge_force_on_tool` — instantaneous force of one tooth (or band);
* :func:`mode_advance` — exact step of the tool's vibration mode under a constant force;
* :func:`history_push` / :func:`history_at` — the tool displacement as a function of
  the (unwrapped) spindle angle, for the regenerative delay of one tooth pitch.

Angles and signs as :mod:`.force` (``phi`` clockwise from +y; forces on the tool).
"""
from __future__ import annotations

import math

import numpy as np

from ..jit import njit
from .effect_model import MAX_PASSES

TWO_PI = 2.0 * math.pi


@njit
def _add_primitives(a: float, b: float, c: float, p: float, sign: float, out: np.ndarray) -> None:
    """``out += sign * F(p)`` with ``F`` the primitives of h cos, h sin, h, cos, sin, 1 (h = a s + b c + c0)."""
    s = math.sin(p)
    co = math.cos(p)
    s2 = 2.0 * s * co
    out[0] += sign * (a * 0.5 * s * s + b * (0.5 * p + 0.25 * s2) + c * s)
    out[1] += sign * (a * (0.5 * p - 0.25 * s2) + b * 0.5 * s * s - c * co)
    out[2] += sign * (-a * co + b * s + c * p)
    out[3] += sign * s
    out[4] += sign * (-co)
    out[5] += sign * p


@njit
def zero_crossings(a: float, b: float, c: float, lo: float, hi: float) -> tuple[float, float]:
    """Zero crossings of ``a sin phi + b cos phi + c`` inside ``(lo, hi)``, ascending; ``hi`` where none.

    They are ``phi = -psi + asin(-c / M)`` and ``phi = -psi + pi - asin(-c / M)`` (mod 2 pi) with
    ``M = hypot(a, b)``, ``psi = atan2(b, a)``: at most one of each family when ``hi - lo < 2 pi``.
    """
    m = math.hypot(a, b)
    r1 = hi
    r2 = hi
    if m > 0.0 and abs(c) < m:
        psi = math.atan2(b, a)
        r = math.asin(-c / m)
        z1 = (r - psi) + TWO_PI * math.ceil((lo - (r - psi)) / TWO_PI)
        z2 = (math.pi - r - psi) + TWO_PI * math.ceil((lo - (math.pi - r - psi)) / TWO_PI)
        r1 = z1 if lo < z1 < hi else hi
        r2 = z2 if lo < z2 < hi else hi
        if r2 < r1:
            r1, r2 = r2, r1
    return r1, r2


@njit
def positive_chip_integrals(a: float, b: float, c: float, lo: float, hi: float, out: np.ndarray) -> None:
    """Add the integrals over ``{phi in [lo, hi] : h(phi) > 0}`` of ``h cos, h sin, h, cos, sin, 1``.

    Parameters
    ----------
    a, b, c : float
        Chip ``h(phi) = a sin phi + b cos phi + c`` [m].
    lo, hi : float
        Angle interval [rad], ``lo <= hi < lo + 2 pi``.
    out : ndarray, shape (6,)
        Accumulator (``m rad`` for the first three, ``rad`` for the last three), updated in place.

    Notes
    -----
    The interval is cut at the zero crossings inside it (:func:`zero_crossings`) and each piece kept
    where ``h`` at its middle is positive.
    """
    if not hi > lo:
        return
    r1, r2 = zero_crossings(a, b, c, lo, hi)
    start = lo
    for i in range(3):
        end = r1 if i == 0 else (r2 if i == 1 else hi)
        if end > start:
            mid = 0.5 * (start + end)
            if a * math.sin(mid) + b * math.cos(mid) + c > 0.0:
                _add_primitives(a, b, c, end, 1.0, out)
                _add_primitives(a, b, c, start, -1.0, out)
            start = end


@njit
def lowest_form(forms: np.ndarray, nf: int, phi: float) -> int:
    """Index of the smallest of the chip forms ``forms[i] = (a, b, c)`` at ``phi`` (the surface that is cut)."""
    s = math.sin(phi)
    c = math.cos(phi)
    best = 0
    low = forms[0, 0] * s + forms[0, 1] * c + forms[0, 2]
    for i in range(1, nf):
        v = forms[i, 0] * s + forms[i, 1] * c + forms[i, 2]
        if v < low:
            low = v
            best = i
    return best


@njit
def chip_now(forms: np.ndarray, nf: int, alpha: float, beta: float, phi: float) -> float:
    """Chip thickness at ``phi``: ``max(alpha min_i form_i(phi) - beta, 0)``, m."""
    i = lowest_form(forms, nf, phi)
    h = forms[i, 0] * math.sin(phi) + forms[i, 1] * math.cos(phi) + forms[i, 2]
    return max(alpha * h - beta, 0.0)


@njit
def envelope_integrals(forms: np.ndarray, nf: int, alpha: float, beta: float, lo: float, hi: float,
                       out: np.ndarray, cuts: np.ndarray) -> None:
    """:func:`positive_chip_integrals` of ``alpha min_i form_i - beta`` (lower envelope of the chip forms).

    Parameters
    ----------
    forms : ndarray, shape (P, 3)
        Chip forms ``(a, b, c)`` [m], one per surface the tooth may cut (the
        surfaces left by the last ``nf`` teeth: multiple regeneration).
    nf : int
        Forms in use (``1 <= nf <= P``).
    alpha, beta : float
        Static-deflection transform (:func:`deflection_factors`).
    lo, hi : float
        Angle interval [rad], ``lo <= hi < lo + 2 pi``.
    out : ndarray, shape (6,)
        Accumulator as :func:`positive_chip_integrals`.
    cuts : ndarray, shape (>= P (P - 1) + 2,)
        Work space.

    Notes
    -----
    The envelope changes form where two forms cross (closed form, :func:`zero_crossings` of their
    difference); between those angles one form is lowest and is integrated exactly.
    """
    if not hi > lo:
        return
    if nf == 1:
        positive_chip_integrals(alpha * forms[0, 0], alpha * forms[0, 1], alpha * forms[0, 2] - beta, lo, hi, out)
        return
    n = 0
    cuts[n] = lo
    n += 1
    for i in range(nf):
        for j in range(i + 1, nf):
            r1, r2 = zero_crossings(forms[i, 0] - forms[j, 0], forms[i, 1] - forms[j, 1], forms[i, 2] - forms[j, 2],
                                    lo, hi)
            if r1 < hi:
                cuts[n] = r1
                n += 1
            if r2 < hi:
                cuts[n] = r2
                n += 1
    cuts[n] = hi
    n += 1
    for i in range(1, n):  # insertion sort
        v = cuts[i]
        j = i - 1
        while j >= 0 and cuts[j] > v:
            cuts[j + 1] = cuts[j]
            j -= 1
        cuts[j + 1] = v
    for k in range(n - 1):
        a = cuts[k]
        b = cuts[k + 1]
        if b > a:
            i = lowest_form(forms, nf, 0.5 * (a + b))
            positive_chip_integrals(alpha * forms[i, 0], alpha * forms[i, 1], alpha * forms[i, 2] - beta, a, b, out)


@njit
def add_piece(
    kt: float, ke: float, kte: float, kre: float, depth: float, forms: np.ndarray, nf: int, alpha: float,
    beta: float, ag: float, bg: float, lo: float, hi: float, radius: float, omega: float, scale: float,
    acc: np.ndarray, tmp: np.ndarray, cuts: np.ndarray,
) -> None:
    """``acc += scale * integral over [lo, hi]`` of (Fx, Fy on the tool, torque, removal rate) d phi.

    Parameters
    ----------
    kt, ke : float
        Tangential coefficient [N/m2] and radial/tangential ratio [1].
    kte, kre : float
        Edge coefficients [N/m] (active where the chip is positive).
    depth : float
        Axial depth of the tooth (or helix band) [m].
    forms, nf, alpha, beta
        Chip ``alpha min_i (a_i sin + b_i cos + c_i) - beta`` [m] (:func:`envelope_integrals`).
    ag, bg : float
        Geometric chip ``ag sin + bg cos`` [m] (removal rate: material removed is geometric).
    lo, hi : float
        Angle piece [rad].
    radius, omega : float
        Tool radius [m], spindle speed [rad/s].
    scale : float
        Weight, e.g. ``1 / (substep angle)`` to get the substep mean.
    acc : ndarray, shape (4,)
        Accumulator: Fx, Fy [N], torque [N.m], removal rate [m3/s] (times ``scale`` rad).
    tmp, cuts : ndarray
        Work space, shapes (6,) and as :func:`envelope_integrals`.
    """
    tmp[:] = 0.0
    envelope_integrals(forms, nf, alpha, beta, lo, hi, tmp, cuts)
    kd = kt * depth
    ed = kte * depth
    rd = kre * depth
    acc[0] += scale * (-kd * tmp[0] - ed * tmp[3] - ke * kd * tmp[1] - rd * tmp[4])
    acc[1] += scale * (kd * tmp[1] + ed * tmp[4] - ke * kd * tmp[0] - rd * tmp[3])
    acc[2] += scale * radius * (kd * tmp[2] + ed * tmp[5])
    tmp[:] = 0.0
    positive_chip_integrals(ag, bg, 0.0, lo, hi, tmp)
    acc[3] += scale * depth * radius * omega * tmp[2]


@njit
def edge_force_on_tool(
    kt: float, ke: float, kte: float, kre: float, depth: float, h: float, phi: float,
) -> tuple[float, float, float]:
    """Force of one tooth (or helix band) on the tool [N]: ``Ft = Kt d h + Kte d``, ``Fr = Ke Kt d h + Kre d``.

    The edge terms act only while the chip ``h`` is positive. Returns ``(fx, fy, ft)``.
    """
    if not (h > 0.0 and depth > 0.0):
        return 0.0, 0.0, 0.0
    ft = kt * depth * h + kte * depth
    fr = ke * kt * depth * h + kre * depth
    s = math.sin(phi)
    c = math.cos(phi)
    return -ft * c - fr * s, ft * s - fr * c, ft


@njit
def add_piece_point(
    kt: float, ke: float, kte: float, kre: float, depth: float, h: float, hg: float, phi: float,
    radius: float, omega: float, weight: float, acc: np.ndarray,
) -> None:
    """Point value version of :func:`add_piece` for a spindle that hardly turns within the substep."""
    fx, fy, ft = edge_force_on_tool(kt, ke, kte, kre, depth, h, phi)
    acc[0] += weight * fx
    acc[1] += weight * fy
    acc[2] += weight * ft * radius
    acc[3] += weight * max(hg, 0.0) * depth * radius * omega


@njit
def deflection_factors(kt: float, ke: float, kre: float, depth: float, stiffness: float) -> tuple[float, float]:
    """Static tool deflection of one tooth: chip ``h = alpha h0 - beta`` [-, m].

    The tooth's radial force ``Fr = Ke Kt D h + Kre D`` (``D`` its engaged
    axial depth) pushes the tool away from the surface by ``Fr / k``, which
    removes that much chip: ``h = h0 - Fr / k``, solved for ``h``::

        alpha = 1 / (1 + Ke Kt D / k),  beta = alpha Kre D / k

    ``stiffness <= 0`` is a rigid tool (``alpha = 1, beta = 0``).
    """
    if not stiffness > 0.0:
        return 1.0, 0.0
    alpha = 1.0 / (1.0 + ke * kt * depth / stiffness)
    return alpha, alpha * kre * depth / stiffness


@njit
def mode_advance(q: float, v: float, force: float, wn: float, zeta: float, stiffness: float,
                 dt: float) -> tuple[float, float]:
    """Exact step of ``m q'' + c q' + k q = F`` over ``dt`` with ``F`` constant (underdamped, ``zeta < 1``).

    Parameters
    ----------
    q, v : float
        Displacement [m] and velocity [m/s] at the start.
    force : float
        Force on the tool [N], held over the step.
    wn : float
        Natural angular frequency [rad/s].
    zeta : float
        Damping ratio [1], ``0 <= zeta < 1``.
    stiffness : float
        Modal stiffness ``k`` [N/m].
    dt : float
        Step [s].

    Returns
    -------
    q, v : float
        At the end of the step.
    """
    y0 = q - force / stiffness
    sigma = zeta * wn
    root = math.sqrt(1.0 - zeta * zeta)
    wd = wn * root
    e = math.exp(-sigma * dt)
    s = math.sin(wd * dt)
    c = math.cos(wd * dt)
    y = e * (y0 * c + (v + sigma * y0) / wd * s)
    vv = e * (v * c - (wn * y0 + zeta * v) / root * s)
    return y + force / stiffness, vv


@njit
def history_push(ht: np.ndarray, hx: np.ndarray, hy: np.ndarray, meta: np.ndarray, m: int, theta: float,
                 qx: float, qy: float, gap: float) -> None:
    """Store the tool displacement ``(qx, qy)`` at unwrapped spindle angle ``theta`` for member ``m``.

    A ring buffer per member (``meta[m] = (oldest index, count)``); an entry
    closer than ``gap`` in angle to the newest one is skipped, so a buffer of
    ``C`` entries always spans at least ``C gap`` of spindle angle.
    """
    cap = ht.shape[1]
    head = meta[m, 0]
    cnt = meta[m, 1]
    if cnt > 0:
        last = (head + cnt - 1) % cap
        if theta - ht[m, last] < gap:
            return
    if cnt == cap:
        head = (head + 1) % cap
        cnt -= 1
        meta[m, 0] = head
    i = (head + cnt) % cap
    ht[m, i] = theta
    hx[m, i] = qx
    hy[m, i] = qy
    meta[m, 1] = cnt + 1


@njit
def history_at(ht: np.ndarray, hx: np.ndarray, hy: np.ndarray, meta: np.ndarray, m: int,
               theta: float) -> tuple[float, float]:
    """Tool displacement when the spindle was at ``theta`` (linear between entries; 0 before the first)."""
    cap = ht.shape[1]
    head = meta[m, 0]
    cnt = meta[m, 1]
    if cnt == 0 or theta < ht[m, head]:
        return 0.0, 0.0
    last = (head + cnt - 1) % cap
    if theta >= ht[m, last]:
        return hx[m, last], hy[m, last]
    lo = 0  # logical index with ht <= theta
    hi = cnt - 1  # logical index with ht > theta
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if ht[m, (head + mid) % cap] <= theta:
            lo = mid
        else:
            hi = mid
    i = (head + lo) % cap
    j = (head + hi) % cap
    span = ht[m, j] - ht[m, i]
    u = (theta - ht[m, i]) / span if span > 0.0 else 0.0
    return hx[m, i] + u * (hx[m, j] - hx[m, i]), hy[m, i] + u * (hy[m, j] - hy[m, i])


@njit
def regenerative_displacements(dq: np.ndarray, nf: int, ht: np.ndarray, hx: np.ndarray, hy: np.ndarray,
                               meta: np.ndarray, m: int, theta: float, qx: float, qy: float, pitch: float) -> None:
    """``dq[i] = q(now) - q(at spindle angle theta - (i + 1) pitch)`` for ``i < nf`` [m].

    The surface cut ``i + 1`` teeth back was left where the tool was then.
    """
    for i in range(nf):
        px, py = history_at(ht, hx, hy, meta, m, theta - (i + 1) * pitch)
        dq[i, 0] = qx - px
        dq[i, 1] = qy - py


@njit
def build_forms(forms: np.ndarray, nf: int, back: np.ndarray, dq: np.ndarray, offsets: np.ndarray) -> None:
    """Chip forms of one tooth: the surface cut ``i + 1`` teeth back gives ``c_i . u + off_i + dq_i . u``.

    Parameters
    ----------
    forms : ndarray, shape (P, 3)
        Written: ``(a, b, c)`` of ``a sin phi + b cos phi + c`` [m].
    nf : int
        Surfaces considered (1 = the previous tooth only).
    back : ndarray, shape (P, 2)
        ``c_i``: the tool-centre displacement since the surface cut ``i + 1`` teeth back was left, over
        ``i + 1`` tooth periods [m] (:func:`.kernel.chords_back`; row 0 the feed per tooth, the tooth-period
        chord; ``(i + 1)`` times it at a constant feed).
    dq : ndarray, shape (P, 2)
        Regenerative displacements (:func:`regenerative_displacements`) [m].
    offsets : ndarray, shape (P,)
        Runout chip offsets ``r_j - r_(j-i-1)`` of the tooth [m].
    """
    for i in range(nf):
        forms[i, 0] = back[i, 0] + dq[i, 0]
        forms[i, 1] = back[i, 1] + dq[i, 1]
        forms[i, 2] = offsets[i]


@njit
def effect_workspace(nmax: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                         np.ndarray, np.ndarray]:
    """Zeroed work space of the effect kernels for tools of up to ``nmax`` teeth.

    Returns
    -------
    acc, sub : ndarray, shape (4,)
        Step and substep sums of (Fx, Fy, torque, MRR).
    tmp : ndarray, shape (6,)
        Scratch of :func:`add_piece`.
    cuts : ndarray, shape (MAX_PASSES (MAX_PASSES - 1) + 2,)
        Zero crossings of the generalised chip (:func:`add_piece`).
    forms : ndarray, shape (MAX_PASSES, 3)
        Chip forms (:func:`build_forms`).
    dq : ndarray, shape (MAX_PASSES, 2)
        Regenerative displacements, m.
    dtooth, dsum : ndarray, shape (nmax,)
        Engaged depth per tooth, m.
    """
    return (np.zeros(4), np.zeros(4), np.zeros(6), np.zeros(MAX_PASSES * (MAX_PASSES - 1) + 2),
            np.zeros((MAX_PASSES, 3)), np.zeros((MAX_PASSES, 2)), np.zeros(nmax), np.zeros(nmax))
