"""Compiled step of the path mode with the effect terms on (runout, helix, edge force, deflection, chatter).

Used by :class:`.path_component.PathCuttingLoad` in place of
:func:`.path_kernel.path_step` when one of those terms is on; the path
projection, substeps and engagement intervals are those of
:mod:`.path_kernel`, the chip, edge forces, helix bands, static deflection
and tool mode those of :mod:`.kernel_effects` (shared scalar kernels in
:mod:`.chip`), so both modes model the same physics:

* the instantaneous force of a helical flute (the ``fx``, ``fy`` outputs,
  the peak at entry/exit instants) is integrated exactly over the axial depth
  (:func:`_force_helix_exact`: ``phi(z) = phi_j - z tan(helix) / R`` turns the
  axial integral into an angle integral of the chip's closed forms);
* the substep means (mean force, torque, removal rate, the tool mode's load)
  cut each tooth into helix bands (:func:`.effect_model.helix_bands`),
  band ``b`` at ``phi_j - lag_b`` cutting the material between ``z_lo_b`` and
  ``z_hi_b`` above the tool tip (from the interval's top of material): a
  band's lag spread is averaged out by the mean over the substep;
* in each substep, every band's sweep ``[phi_a, phi_b]`` is intersected with
  the engagement intervals and each piece integrated exactly with the
  generalised chip (:func:`.chip.add_piece`); the tooth's engaged depth for
  the static deflection is the sum over its bands of the deepest piece with a
  positive chip at its middle;
* the peak force is searched at the substep ends and where a band's piece
  starts or ends inside the substep (entry/exit instants); for a helix the
  substep ends, shared by all bands and flutes, are evaluated once each
  (:func:`_force_helix_exact` with its work space allocated once per step);
* the tool mode advances exactly per substep under the substep-mean force
  (:func:`.chip.mode_advance`); the regenerative displacement is held at its
  substep-middle value over a substep (exact at the instants ``t + k h / n``).
"""
from __future__ import annotations

import math

import numpy as np

from ..jit import njit
from ..jit_cache import guard_cache
from . import chip, effect_model, kernel, path_kernel
from .chip import add_piece, add_piece_point, build_forms, chip_now, deflection_factors, edge_force_on_tool, \
    effect_workspace, history_push, mode_advance, regenerative_displacements
from .effect_model import (
    CHATTER_SUBSTEPS_PER_PERIOD, E_KC, E_STIFF, E_TANH, E_WN, E_ZETA, MAX_BANDS, MAX_PASSES, helix_bands,
)
from .kernel import chord_feed, chords_back, stalled_cut
from .path_kernel import (
    ERR_OFF_PATH, ERR_STALLED, ERR_SUBSTEPS, INCLUSIVE_TOL, PAR_FLUTES, PAR_RADIUS, PAR_STEPS, ST_HISTORY, ST_THETA,
    blank_member, drop_history, fail_member, interval_buffers, member_motion, substeps, table_at, write_member,
)

TWO_PI = 2.0 * math.pi
#: Spindle turn per substep below which the point value replaces the exact integral, rad.
SHORT_SPAN = 1e-9
#: Most angle pieces of one helical flute at one instant (engagement intervals x turns of the flute).
HELIX_PIECES = 64


@njit
def _top_at(phi: float, ia: np.ndarray, ib: np.ndarray, it: np.ndarray, cnt: int) -> float:
    """Highest top of material among the intervals containing ``phi`` (inclusive), m; ``-inf`` in air."""
    best = -math.inf
    for k in range(cnt):
        a = ia[k]
        b = ib[k]
        inside = (a - INCLUSIVE_TOL <= phi <= b + INCLUSIVE_TOL) or (phi + TWO_PI <= b + INCLUSIVE_TOL) \
            or (phi - TWO_PI >= a - INCLUSIVE_TOL)
        if inside and it[k] > best:
            best = it[k]
    return best


@njit
def _band_depth(top: float, bottom: float, ztip: float, z_lo: float, z_hi: float) -> float:
    """Depth of material with top ``top`` within the band ``[z_lo, z_hi)`` above the tip, m."""
    if not top > bottom:
        return 0.0
    return max(min(top - ztip, z_hi) - max(bottom - ztip, z_lo), 0.0)


@njit
def _wrap(p: float) -> float:
    return p - math.floor(p / TWO_PI) * TWO_PI


@njit
def _helix_pieces(phi_j: float, tanh: float, radius: float, ia: np.ndarray, ib: np.ndarray, it: np.ndarray,
                  cnt: int, bottom: float, ztip: float, lo_out: np.ndarray, hi_out: np.ndarray) -> int:
    """Angle pieces swept by a helical flute over the material at one instant; returns how many.

    The flute point at height ``z`` above the tool tip sits at ``phi_j - z tan(helix) / R``. For
    each engagement interval ``q`` the flute is in material for ``z`` in ``[max(bottom - ztip, 0),
    top_q - ztip]``, i.e. over an angle range of the same length times ``tan(helix) / R``; its
    intersections with ``[alpha_q, beta_q] + 2 pi k`` are written to ``lo_out``, ``hi_out`` (rad,
    unwrapped near ``phi_j``). The intervals of a station are disjoint, so the pieces are too.
    """
    n = 0
    z1 = max(bottom - ztip, 0.0)
    for q in range(cnt):
        z2 = it[q] - ztip
        if not z2 > z1:
            continue
        if tanh > 0.0:
            plo = phi_j - z2 * tanh / radius
            phi_hi = phi_j - z1 * tanh / radius
        else:
            plo = phi_j - z1 * tanh / radius
            phi_hi = phi_j - z2 * tanh / radius
        k0 = int(math.floor((plo - ib[q]) / TWO_PI))
        k1 = int(math.ceil((phi_hi - ia[q]) / TWO_PI))
        for k in range(k0, k1 + 1):
            lo = max(plo, ia[q] + k * TWO_PI)
            hi = min(phi_hi, ib[q] + k * TWO_PI)
            if hi > lo and n < lo_out.shape[0]:
                lo_out[n] = lo
                hi_out[n] = hi
                n += 1
    return n


@njit
def _max_chip(forms: np.ndarray, nf: int, alpha: float, beta: float, lo: float, hi: float) -> float:
    """Largest chip ``alpha min_i form_i - beta`` on ``[lo, hi]``: at the ends, the middle and each form's crest."""
    best = max(chip_now(forms, nf, alpha, beta, lo), chip_now(forms, nf, alpha, beta, hi),
               chip_now(forms, nf, alpha, beta, 0.5 * (lo + hi)))
    for i in range(nf):
        crest = math.atan2(forms[i, 0], forms[i, 1])  # a sin + b cos is largest there
        crest += TWO_PI * math.ceil((lo - crest) / TWO_PI)
        if crest <= hi:
            best = max(best, chip_now(forms, nf, alpha, beta, crest))
    return best


@njit
def helix_workspace() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Work space of :func:`_force_helix_exact`, allocated once per step call, not per evaluation.

    Returns
    -------
    lo, hi : ndarray, shape (HELIX_PIECES,)
        Angle pieces of one flute, rad.
    pint : ndarray, shape (HELIX_PIECES, 6)
        Chip integrals of each piece (:func:`.chip.envelope_integrals`).
    tmp : ndarray, shape (6,)
        Scratch.
    cuts : ndarray, shape (MAX_PASSES (MAX_PASSES - 1) + 2,)
        Scratch of :func:`.chip.envelope_integrals`.
    """
    return (np.empty(HELIX_PIECES), np.empty(HELIX_PIECES), np.zeros((HELIX_PIECES, 6)), np.zeros(6),
            np.zeros(MAX_PASSES * (MAX_PASSES - 1) + 2))


@njit
def _piece_force(kt: float, ke: float, kte: float, kre: float, scale: float, tmp: np.ndarray) -> tuple[float, float]:
    """Fx, Fy of :func:`.chip.add_piece` (depth 1) from the piece's chip integrals ``tmp``, N (same operations)."""
    kd = kt * 1.0
    ed = kte * 1.0
    rd = kre * 1.0
    return (scale * (-kd * tmp[0] - ed * tmp[3] - ke * kd * tmp[1] - rd * tmp[4]),
            scale * (kd * tmp[1] + ed * tmp[4] - ke * kd * tmp[0] - rd * tmp[3]))


@njit
def _force_helix_exact(
    phi0: float, flutes: int, pitch: float, tanh: float, radius: float, ia: np.ndarray, ib: np.ndarray,
    it: np.ndarray, cnt: int, ra: np.ndarray, rb: np.ndarray, rt: np.ndarray, rcnt: int, treach: np.ndarray,
    bottom: float, ztip: float, back: np.ndarray, dq: np.ndarray, nf: int,
    toff: np.ndarray, kt: float, ke: float, kte: float, kre: float, stiff: float, forms: np.ndarray,
    lo: np.ndarray, hi: np.ndarray, pint: np.ndarray, tmp: np.ndarray, cuts: np.ndarray, detail: bool,
) -> tuple[float, float, float, float, int]:
    """Force on the tool at one instant (tooth 0 at ``phi0``) of helical flutes, exact over the axial depth.

    Returns as :func:`force_at_effects`; a flute ``j`` with ``treach[j] > 0`` is cut over the runout
    ring's intervals ``ra, rb, rt, rcnt`` (see there).

    With ``phi(z) = phi_j - z tan(helix) / R`` (Altintas, *Manufacturing Automation*, ch. 2) the
    force of flute ``j`` is ``int dF(phi(z)) dz = R / |tan(helix)| int dF(phi) dphi`` over the
    pieces of :func:`_helix_pieces`, with ``dF`` the force per unit depth of the generalised chip
    (runout, regeneration, static deflection, edge terms); the angle integrals are the closed forms
    of :func:`.chip.add_piece` (zero crossings and envelope of the chip forms located exactly). The
    engaged depth of a flute (static deflection) is ``R / |tan(helix)|`` times the angle measure of
    its pieces with a positive geometric chip.

    ``lo``, ``hi``, ``pint``, ``tmp``, ``cuts`` are work space (:func:`helix_workspace`). The chip
    integrals of a piece are computed once for a rigid tool (``alpha = 1, beta = 0``: the geometric
    chip is the cut chip) and twice with a static deflection. With ``detail`` False only ``fx``, ``fy``
    are wanted (the peak search): the largest chip is not searched and returned as 0.
    """
    if cnt == 0 and rcnt == 0:
        return 0.0, 0.0, 0.0, 0.0, 0
    scale = radius / abs(tanh)
    rigid = not stiff > 0.0
    fx = 0.0
    fy = 0.0
    hmax = 0.0
    dmax = 0.0
    n_in = 0
    for j in range(flutes):
        if treach[j] > 0.0:
            np_ = _helix_pieces(_wrap(phi0 + j * pitch), tanh, radius, ra, rb, rt, rcnt, bottom, ztip, lo, hi)
        else:
            np_ = _helix_pieces(_wrap(phi0 + j * pitch), tanh, radius, ia, ib, it, cnt, bottom, ztip, lo, hi)
        if np_ == 0:
            continue
        build_forms(forms, nf, back, dq, toff[j])
        depth = 0.0
        for i in range(np_):
            pint[i, :] = 0.0
            chip.envelope_integrals(forms, nf, 1.0, 0.0, lo[i], hi[i], pint[i], cuts)
            depth += scale * pint[i, 5]
        if not depth > 0.0:
            continue
        alpha, beta = deflection_factors(kt, ke, kre, depth, stiff)
        ax = 0.0
        ay = 0.0
        engaged = 0.0
        for i in range(np_):
            if rigid:  # alpha = 1, beta = 0: the integrals of the depth pass
                w = pint[i]
            else:
                tmp[:] = 0.0
                chip.envelope_integrals(forms, nf, alpha, beta, lo[i], hi[i], tmp, cuts)
                w = tmp
            px, py = _piece_force(kt, ke, kte, kre, scale, w)
            ax += px
            ay += py
            if w[5] > 0.0:
                engaged += scale * w[5]
                if detail:
                    hmax = max(hmax, _max_chip(forms, nf, alpha, beta, lo[i], hi[i]))
        fx += ax
        fy += ay
        if engaged > 0.0:
            n_in += 1
            dmax = max(dmax, engaged)
    return fx, fy, dmax, hmax, n_in


@njit
def force_at_effects(
    phi0: float, flutes: int, pitch: float, nb: int, lag: np.ndarray, z_lo: np.ndarray, z_hi: np.ndarray,
    ia: np.ndarray, ib: np.ndarray, it: np.ndarray, cnt: int, ra: np.ndarray, rb: np.ndarray, rt: np.ndarray,
    rcnt: int, treach: np.ndarray, bottom: float, ztip: float, back: np.ndarray,
    dq: np.ndarray, nf: int, toff: np.ndarray, kt: float, ke: float, kte: float, kre: float, stiff: float,
    dsum: np.ndarray, forms: np.ndarray,
) -> tuple[float, float, float, float, int]:
    """Force on the tool at one instant (tooth 0 at ``phi0``) with the effect terms, teeth cut in bands.

    ``ia, ib, it, cnt`` are the engagement intervals at the radius, ``ra, rb, rt, rcnt`` those of the
    runout ring (:meth:`.table.EngagementTable.runout_ring`): tooth ``j`` is tested for material in the
    ring where ``treach[j] > 0`` (:func:`.effect_model.runout_reach`), and the chip minimum decides.
    ``back`` holds the tool-centre displacements over the last tooth periods
    (:func:`.chip.build_forms`), ``dq`` the regenerative displacements at that instant, ``toff`` the
    runout offsets (nmax, passes) of the member, ``forms`` is work space. Used
    for straight flutes (one band); a helical flute is integrated exactly over
    the axial depth by :func:`_force_helix_exact` instead (the step calls
    that one directly: one small function per case keeps the compiled
    straight-flute step as fast as it was).

    Returns
    -------
    fx, fy : float
        Force on the tool, N.
    depth, chip : float
        Largest engaged axial depth of a tooth and largest chip, m.
    engaged : int
        Teeth with a band in material with a positive chip.
    """
    if cnt == 0 and rcnt == 0:
        return 0.0, 0.0, 0.0, 0.0, 0
    for j in range(flutes):
        dsum[j] = 0.0
        build_forms(forms, nf, back, dq, toff[j])
        for b in range(nb):
            phi = _wrap(phi0 + j * pitch - lag[b])
            if treach[j] > 0.0:
                d = _band_depth(_top_at(phi, ra, rb, rt, rcnt), bottom, ztip, z_lo[b], z_hi[b])
            else:
                d = _band_depth(_top_at(phi, ia, ib, it, cnt), bottom, ztip, z_lo[b], z_hi[b])
            if d > 0.0 and chip_now(forms, nf, 1.0, 0.0, phi) > 0.0:
                dsum[j] += d
    fx = 0.0
    fy = 0.0
    hmax = 0.0
    dmax = 0.0
    n_in = 0
    for j in range(flutes):
        if not dsum[j] > 0.0:
            continue
        alpha, beta = deflection_factors(kt, ke, kre, dsum[j], stiff)
        build_forms(forms, nf, back, dq, toff[j])
        dj = 0.0
        for b in range(nb):
            phi = _wrap(phi0 + j * pitch - lag[b])
            if treach[j] > 0.0:
                d = _band_depth(_top_at(phi, ra, rb, rt, rcnt), bottom, ztip, z_lo[b], z_hi[b])
            else:
                d = _band_depth(_top_at(phi, ia, ib, it, cnt), bottom, ztip, z_lo[b], z_hi[b])
            if not d > 0.0:
                continue
            hc = chip_now(forms, nf, alpha, beta, phi)
            if not (hc > 0.0 and chip_now(forms, nf, 1.0, 0.0, phi) > 0.0):
                continue
            a, c, _ = edge_force_on_tool(kt, ke, kte, kre, d, hc, phi)
            fx += a
            fy += c
            hmax = max(hmax, hc)
            dj += d
        if dj > 0.0:
            n_in += 1
            dmax = max(dmax, dj)
    return fx, fy, dmax, hmax, n_in


@njit
def path_step_effects(
    h: float, inp: np.ndarray, par: np.ndarray, st: np.ndarray, out: np.ndarray, engaged: np.ndarray,
    verts: np.ndarray, vs: np.ndarray, ds: float, count: np.ndarray, alpha: np.ndarray, beta: np.ndarray,
    top: np.ndarray, z_floor: float, stock_top: float, reach_margin: float, tolerance: float, max_substeps: int,
    coef: np.ndarray, epar: np.ndarray, toff: np.ndarray, passes: np.ndarray, mode: np.ndarray, ht: np.ndarray,
    hx: np.ndarray, hy: np.ndarray, meta: np.ndarray, angle: np.ndarray, gap: np.ndarray, status: np.ndarray,
    rcount: np.ndarray, ralpha: np.ndarray, rbeta: np.ndarray, rtop: np.ndarray, treach: np.ndarray,
) -> int:
    """Advance every member by one step ``h`` with the effect terms; write outputs and state in place.

    Parameters
    ----------
    h, inp, par, st, out, engaged, verts, vs, ds, count, alpha, beta, top, z_floor, reach_margin, tolerance, \
max_substeps
        As :func:`.path_kernel.path_step` (``inp[3]`` is the actual spindle speed).
    stock_top : float
        Stock block top, m (helix bands reach up to it).
    coef : ndarray, shape (4, B)
        ``Kt`` [N/m2], ``Ke`` [1], ``Kte``, ``Kre`` [N/m], wear applied.
    epar : ndarray, shape (11, B)
        :meth:`.effect_model.EffectParameters.packed`.
    toff : ndarray, shape (B, nmax, MAX_PASSES)
        Runout chip offsets (:meth:`.effect_model.EffectParameters.runout_offsets`), m.
    passes : ndarray of int, shape (B,)
        Surfaces a tooth may cut (:meth:`.effect_model.EffectParameters.passes`).
    mode : ndarray, shape (B, 4)
        Tool vibration (qx, qy, vx, vy), updated.
    ht, hx, hy, meta
        Vibration history (:class:`.effect_model.EffectState`), updated.
    angle : ndarray, shape (B,)
        Unwrapped spindle angle at the start of the step, rad (not advanced here).
    gap : ndarray, shape (B,)
        History spacing, rad.
    status : ndarray of int64, shape (B,)
        Error kind of each member that fails in this step, as in :func:`.path_kernel.path_step`.
    rcount, ralpha, rbeta, rtop
        The runout ring's table arrays (:meth:`.table.EngagementTable.runout_ring`, the same stations), read
        only for the teeth with ``treach > 0`` (any table of the same stations when there is none).
    treach : ndarray, shape (B, nmax)
        How far beyond the radius each tooth stands out (:func:`.effect_model.runout_reach`), m: a tooth
        with ``treach > 0`` is tested for material in the runout ring, the others at the radius.

    Returns
    -------
    int
        Number of members that failed in this step (see :func:`.path_kernel.path_step`).
    """
    batch = inp.shape[1]
    ia, ib, it, ja, jb, jt = interval_buffers(alpha.shape[1])
    ra, rb, rt, rja, rjb, rjt = interval_buffers(ralpha.shape[1])
    acc, sub, tmp, cuts, forms, dq, dtooth, dsum = effect_workspace(toff.shape[1])
    cuts_forms = np.zeros((MAX_PASSES, 3))
    back = np.zeros((MAX_PASSES, 2))
    hlo, hhi, pint, htmp, hcuts = helix_workspace()
    lag = np.zeros(MAX_BANDS)
    z_lo = np.zeros(MAX_BANDS)
    z_hi = np.zeros(MAX_BANDS)
    bad = 0
    for m in range(batch):
        x1, y1, z1 = inp[0, m], inp[1, m], inp[2, m]
        om = max(inp[3, m], 0.0)
        if not (math.isfinite(x1) and math.isfinite(y1) and math.isfinite(z1) and math.isfinite(om)):
            blank_member(out, engaged, m)  # an upstream failure: this member is out, the others go on
            drop_history(st, m)
            continue
        radius = par[PAR_RADIUS, m]
        flutes = int(par[PAR_FLUTES, m])
        steps = par[PAR_STEPS, m]
        kt, ke, kte, kre = coef[0, m], coef[1, m], coef[2, m], coef[3, m]
        stiff = epar[E_STIFF, m]
        wn = epar[E_WN, m]
        chat = wn > 0.0
        nf = passes[m]
        z0, ddx, ddy, ddz, move, s0, seg, s1, dist = member_motion(st, m, x1, y1, z1, reach_margin, verts, vs, ds,
                                                                   count)
        pitch = TWO_PI / flutes
        n_mode = math.ceil(h * wn / TWO_PI * CHATTER_SUBSTEPS_PER_PERIOD - 1e-9)
        n = int(max(substeps(om, h, pitch, steps, move, radius), n_mode))
        if n > max_substeps:
            bad += fail_member(status, out, engaged, m, ERR_SUBSTEPS)  # this member fails; the others go on
            drop_history(st, m)
            continue
        fxt, fyt = chord_feed(st[ST_HISTORY:, m], ddx, ddy, h, om, flutes)  # the tooth-period chord
        # the surfaces left 1 .. nf teeth back: the tool-centre displacement since each was left
        chords_back(st[ST_HISTORY:, m], ddx, ddy, h, om, flutes, fxt, fyt, nf, back)
        theta0 = st[ST_THETA, m]
        span = om * h / n
        dt = h / n
        # helix bands for this step
        tanh = epar[E_TANH, m]
        helix = tanh != 0.0
        nb, dz = helix_bands(tanh, radius, pitch, steps, stock_top - min(z0, z1))
        for b in range(nb):
            lag[b] = 0.0
            z_lo[b] = 0.0
            z_hi[b] = math.inf
        if math.isfinite(dz):
            for b in range(nb):
                lag[b] = (b + 0.5) * dz * tanh / radius
                z_lo[b] = b * dz
                if b < nb - 1:
                    z_hi[b] = (b + 1) * dz
        qx, qy, vx, vy = mode[m, 0], mode[m, 1], mode[m, 2], mode[m, 3]
        dq[:] = 0.0
        acc[:] = 0.0
        peak = 0.0
        f_end_x = 0.0
        f_end_y = 0.0
        d_end = 0.0
        h_end = 0.0
        n_end = 0
        ringed = False  # a tooth of this member is tested in the runout ring
        for j in range(flutes):
            if treach[m, j] > 0.0:
                ringed = True
        any_material = False
        for k in range(n):
            f_mid = (k + 0.5) / n
            s_mid = s0 + f_mid * (s1 - s0)
            ztip = z0 + f_mid * ddz
            bottom = max(ztip, z_floor)
            cm = table_at(s_mid, ds, count, alpha, beta, top, ia, ib, it)
            cr = table_at(s_mid, ds, rcount, ralpha, rbeta, rtop, ra, rb, rt) if ringed else 0
            if chat:
                regenerative_displacements(dq, nf, ht, hx, hy, meta, m, angle[m] + span * (k + 0.5),
                                           qx + 0.5 * dt * vx, qy + 0.5 * dt * vy, pitch)
            sub[:] = 0.0
            at_start = False  # a helix band's piece starts at the substep's first instant
            at_end = False  # ... ends at its last instant
            if cm > 0 or cr > 0:
                any_material = True
                phi_k = theta0 + om * h * k / n
                # engaged depth per tooth (static deflection): deepest piece with a chip per band
                for j in range(flutes):
                    dtooth[j] = 0.0
                    if not stiff > 0.0:
                        continue
                    if treach[m, j] > 0.0:  # a tooth standing out by runout: tested in the runout ring
                        xa, xb, xt, xc = ra, rb, rt, cr
                    else:
                        xa, xb, xt, xc = ia, ib, it, cm
                    build_forms(forms, nf, back, dq, toff[m, j])
                    for b in range(nb):
                        pa = _wrap(phi_k + j * pitch - lag[b])
                        if span < SHORT_SPAN:
                            pm = pa + 0.5 * span
                            d = _band_depth(_top_at(pm, xa, xb, xt, xc), bottom, ztip, z_lo[b], z_hi[b])
                            if d > 0.0 and chip_now(forms, nf, 1.0, 0.0, pm) > 0.0:
                                dtooth[j] += d
                            continue
                        pb = pa + span
                        deepest = 0.0
                        for q in range(xc):
                            d = _band_depth(xt[q], bottom, ztip, z_lo[b], z_hi[b])
                            if not d > deepest:
                                continue
                            for shift in (-TWO_PI, 0.0, TWO_PI):
                                lo = max(pa, xa[q] + shift)
                                hi = min(pb, xb[q] + shift)
                                if not hi > lo:
                                    continue
                                if chip_now(forms, nf, 1.0, 0.0, 0.5 * (lo + hi)) > 0.0:
                                    deepest = d
                                    break
                        dtooth[j] += deepest
                for j in range(flutes):
                    al, be = deflection_factors(kt, ke, kre, dtooth[j], stiff)
                    if treach[m, j] > 0.0:
                        xa, xb, xt, xc = ra, rb, rt, cr
                    else:
                        xa, xb, xt, xc = ia, ib, it, cm
                    build_forms(forms, nf, back, dq, toff[m, j])
                    for b in range(nb):
                        if span < SHORT_SPAN:
                            pm = _wrap(phi_k + 0.5 * span + j * pitch - lag[b])
                            d = _band_depth(_top_at(pm, xa, xb, xt, xc), bottom, ztip, z_lo[b], z_hi[b])
                            if d > 0.0:
                                sn = math.sin(pm)
                                cs = math.cos(pm)
                                add_piece_point(kt, ke, kte, kre, d, chip_now(forms, nf, al, be, pm),
                                                fxt * sn + fyt * cs, pm, radius, om, 1.0, sub)
                            continue
                        pa = _wrap(phi_k + j * pitch - lag[b])
                        pb = pa + span
                        for q in range(xc):
                            d = _band_depth(xt[q], bottom, ztip, z_lo[b], z_hi[b])
                            if not d > 0.0:
                                continue
                            for shift in (-TWO_PI, 0.0, TWO_PI):
                                lo = max(pa, xa[q] + shift)
                                hi = min(pb, xb[q] + shift)
                                if not hi > lo:
                                    continue
                                add_piece(kt, ke, kte, kre, d, forms, nf, al, be, fxt, fyt, lo, hi, radius, om,
                                          1.0 / span, sub, tmp, cuts)
                                # entry/exit instants (engaged side: interval ends are inclusive), not the
                                # step start t; also where this band's chip is 0 (the other bands may be loaded)
                                for edge in (lo, hi):
                                    if edge == pa and k == 0:
                                        continue
                                    if helix and (edge == pa or edge == pb):
                                        # the substep's first or last instant: the same for every band and
                                        # flute, evaluated once below (the helix force is continuous in the
                                        # angle, the bands' copies differ by rounding of the angle only)
                                        at_start = at_start or edge == pa
                                        at_end = at_end or edge == pb
                                        continue
                                    if helix:
                                        fx, fy, _, _, _ = _force_helix_exact(
                                            edge - j * pitch + lag[b], flutes, pitch, tanh, radius, ia, ib, it, cm,
                                            ra, rb, rt, cr, treach[m], bottom, ztip, back, dq, nf, toff[m], kt, ke,
                                            kte, kre, stiff, cuts_forms, hlo, hhi, pint, htmp, hcuts, False)
                                    else:
                                        fx, fy, _, _, _ = force_at_effects(
                                            edge - j * pitch + lag[b], flutes, pitch, nb, lag, z_lo, z_hi, ia, ib,
                                            it, cm, ra, rb, rt, cr, treach[m], bottom, ztip, back, dq, nf, toff[m],
                                            kt, ke, kte, kre, stiff, dsum, cuts_forms)
                                    peak = max(peak, math.sqrt(fx * fx + fy * fy))
                for edge, hit in ((phi_k, at_start), (phi_k + span, at_end)):
                    if hit:
                        fx, fy, _, _, _ = _force_helix_exact(
                            edge, flutes, pitch, tanh, radius, ia, ib, it, cm, ra, rb, rt, cr, treach[m], bottom,
                            ztip, back, dq, nf, toff[m],
                            kt, ke, kte, kre, stiff, cuts_forms, hlo, hhi, pint, htmp, hcuts, False)
                        peak = max(peak, math.sqrt(fx * fx + fy * fy))
            for i in range(4):
                acc[i] += sub[i]
            if chat:
                qx, vx = mode_advance(qx, vx, sub[0], wn, epar[E_ZETA, m], epar[E_KC, m], dt)
                qy, vy = mode_advance(qy, vy, sub[1], wn, epar[E_ZETA, m], epar[E_KC, m], dt)
                theta1 = angle[m] + span * (k + 1)
                history_push(ht, hx, hy, meta, m, theta1, qx, qy, gap[m])
                regenerative_displacements(dq, nf, ht, hx, hy, meta, m, theta1, qx, qy, pitch)
            # the instant t + (k + 1) h / n
            f1 = (k + 1.0) / n
            cj = table_at(s0 + f1 * (s1 - s0), ds, count, alpha, beta, top, ja, jb, jt)
            rcj = table_at(s0 + f1 * (s1 - s0), ds, rcount, ralpha, rbeta, rtop, rja, rjb, rjt) if ringed else 0
            if cj > 0 or rcj > 0:
                any_material = True
                zt1 = z0 + f1 * ddz
                if helix:
                    fx, fy, dm, hm, ne = _force_helix_exact(
                        theta0 + om * h * f1, flutes, pitch, tanh, radius, ja, jb, jt, cj, rja, rjb, rjt, rcj,
                        treach[m], max(zt1, z_floor), zt1,
                        back, dq, nf, toff[m], kt, ke, kte, kre, stiff, cuts_forms, hlo, hhi, pint, htmp, hcuts,
                        True)
                else:
                    fx, fy, dm, hm, ne = force_at_effects(
                        theta0 + om * h * f1, flutes, pitch, nb, lag, z_lo, z_hi, ja, jb, jt, cj, rja, rjb, rjt, rcj,
                        treach[m], max(zt1, z_floor),
                        zt1, back, dq, nf, toff[m], kt, ke, kte, kre, stiff, dsum, cuts_forms)
            else:
                fx, fy, dm, hm, ne = 0.0, 0.0, 0.0, 0.0, 0
            peak = max(peak, math.sqrt(fx * fx + fy * fy))
            if k == n - 1:
                f_end_x, f_end_y, d_end, h_end, n_end = fx, fy, dm, hm, ne
        if any_material and dist > tolerance:
            bad += fail_member(status, out, engaged, m, ERR_OFF_PATH)  # this member fails; the others go on
            drop_history(st, m)
            continue
        if stalled_cut(om, peak, acc[0], acc[1]):
            bad += fail_member(status, out, engaged, m, ERR_STALLED)  # a crash: this member fails
            drop_history(st, m)
            continue
        write_member(out, st, engaged, m, f_end_x, f_end_y, peak, acc, n, om, d_end, h_end, n_end, theta0, h,
                     x1, y1, z1, s1, seg, dist)
        mode[m, 0], mode[m, 1], mode[m, 2], mode[m, 3] = qx, qy, vx, vy
    return bad


# the cached step links the shared kernels' code: recompile it when their modules change
guard_cache(path_step_effects, path_kernel, kernel, chip, effect_model)
