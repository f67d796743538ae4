"""One communication step of the cutting mechanics with the effect terms on (Z-map mode).

Used by :class:`.component.CuttingLoad` when runout, helix, edge force,
tool deflection or chatter is on (wear and spindle droop alone only change
``Kt`` and the spindle speed and use :func:`.kernel.cut_step`). Same time
discretisation as :mod:`.kernel`; the differences:

* **Cutting edges** — each tooth is cut into helix bands (:func:`.effect_model.helix_bands`):
  band ``b`` of tooth ``j`` sits at ``phi_j - lag_b`` and cuts the material
  between ``b dz`` and ``(b + 1) dz`` above the tool tip (a straight tooth is
  one band). The geometry (axial depth per band at the substep instants,
  entry/exit instants located to 1/4096 substep) is numpy, vectorised over
  members, instants and bands, as :func:`.kernel.cut_step`.
* **Chip** — ``h = alpha_j min_i (c_i . u + off_ji + dq_i . u) - beta_j``
  clipped at 0, ``u = (sin phi, cos phi)``: tooth ``j`` cuts the lowest of the
  surfaces left by the last teeth (``i = 0``: the previous one; more with
  runout or chatter, :meth:`.effect_model.EffectParameters.passes`), with
  ``c_i`` the tool-centre displacement over the last ``i + 1`` tooth periods
  (``c_0`` the feed per tooth; :func:`.kernel.chords_back`, ``(i + 1) c_0``
  at a constant feed and where the record of the steps does not reach back),
  ``off_ji = r_j - r_(j-i-1)`` the runout offsets,
  ``dq_i`` the regenerative displacement (tool vibration now minus at
  ``i + 1`` pitches of spindle angle ago, held at its substep-middle value
  over a substep) and ``alpha_j, beta_j`` the static deflection of tooth ``j``
  (:func:`.chip.deflection_factors`, with the tooth's engaged depth ``D_j``).
* **Material** — a tooth that stands out by runout is tested for material
  beyond ``R`` (:func:`.effect_model.runout_reach`: against the nominal
  sweeps by the largest runout offset of the chip's surfaces, against the
  Z-map by its own offset), the others at ``R``; the chip minimum then
  decides (at a turn of the path the nominal test dropped chips of the long tooth).
* **Means** — each piece of a substep is integrated exactly
  (:func:`.chip.add_piece`, zero crossings of the generalised chip located in
  closed form); the removal rate uses the geometric chip ``c . u`` (material
  removed is geometric, the effect terms move force, not volume).
* **Tool mode** — advanced exactly over each substep under the substep-mean
  force (:func:`.chip.mode_advance`), its history kept per spindle angle.

The sequential part (per member, per substep) is compiled
(:func:`_integrate`).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..errors import CncTwinError
from ..jit import njit
from ..jit_cache import guard_cache
from . import chip, effect_model
from .chip import add_piece, add_piece_point, build_forms, chip_now, deflection_factors, edge_force_on_tool, \
    effect_workspace, history_push, mode_advance, regenerative_displacements
from .effect_model import HISTORY_PER_PITCH, MAX_PASSES, EffectParameters, EffectState, helix_bands, runout_reach
from .engagement import NearField, tooth_depth
from .kernel import SECTION_ROUNDS, SECTIONS, StepResult, step_kinematics, substep_counts
from .stock import ZMapStock

#: Spindle turn per substep below which the point value replaces the exact integral, rad.
SHORT_SPAN = 1e-9


def band_layout(eff: EffectParameters, radius: np.ndarray, pitch: np.ndarray, steps: np.ndarray,
                height: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Helix bands of every member for one step.

    Parameters
    ----------
    eff : EffectParameters
    radius, pitch, steps : ndarray, shape (B,)
        Tool radius [m], tooth pitch [rad], angle steps per tooth.
    height : ndarray, shape (B,)
        Stock top above the lowest tool tip of the step [m].

    Returns
    -------
    z_lo, z_hi, lag : ndarray, shape (B, nb)
        Band limits above the tool tip [m] and lag angle [rad] (``z_lo = z_hi = inf`` for unused bands).
    count : ndarray of int, shape (B,)
        Bands per member.
    """
    B = radius.shape[0]
    layout = [helix_bands(float(eff.tan_helix[m]), float(radius[m]), float(pitch[m]), float(steps[m]),
                          float(height[m])) for m in range(B)]
    count = np.array([c for c, _ in layout], dtype=np.int64)
    dz = np.array([d for _, d in layout])
    nb = int(count.max())
    b = np.arange(nb)[None, :]
    used = b < count[:, None]
    finite = np.isfinite(dz)[:, None]
    dz_f = np.where(finite, dz[:, None], 0.0)
    z_lo = np.where(used, np.where(b == 0, 0.0, b * dz_f), np.inf)
    z_hi = np.where(used & (b < count[:, None] - 1), (b + 1) * dz_f, np.inf)
    lag = np.where(used & finite, (b + 0.5) * dz_f * eff.tan_helix[:, None] / radius[:, None], 0.0)
    return z_lo, z_hi, lag, count


def _band_depth(stock: ZMapStock, near: NearField, member: np.ndarray, centre: np.ndarray, phi: np.ndarray,
                radius: np.ndarray, z_lo: np.ndarray, z_hi: np.ndarray, active: np.ndarray,
                reach: np.ndarray, reach_stock: np.ndarray) -> np.ndarray:
    """Axial depth of material within the band ``[z_lo, z_hi)`` above the tool tip at each periphery point, m.

    The points are tested ``reach`` (the recent sweeps of ``radius``) and ``reach_stock`` (the Z-map) from
    the axis (:func:`.effect_model.runout_reach` added to the radius).
    """
    raw = tooth_depth(stock, near, member, centre, phi, radius, active, reach, reach_stock)
    ztip = centre[:, 2]
    bottom = np.maximum(ztip, stock.lower[member, 2])
    d = np.minimum(raw + bottom - ztip, z_hi) - np.maximum(bottom - ztip, z_lo)
    return np.where(raw > 0.0, np.maximum(d, 0.0), 0.0)


def cut_step_effects(
    stock: ZMapStock, near: NearField, p_old: np.ndarray, p_new: np.ndarray, theta0: np.ndarray,
    omega: np.ndarray, h: float, n: int | np.ndarray, radius: np.ndarray, flutes: np.ndarray, steps: np.ndarray,
    coefficients: np.ndarray, eff: EffectParameters, state: EffectState, stock_top: np.ndarray,
    rows: np.ndarray | None = None, feed: np.ndarray | None = None, back: np.ndarray | None = None,
) -> StepResult:
    """Cutting forces with the effect terms while the tool moves linearly from ``p_old`` to ``p_new``.

    Parameters
    ----------
    stock, near, p_old, p_new, theta0, omega, h, n, radius, flutes
        As :func:`.kernel.cut_step` (``omega`` is the actual spindle speed;
        ``n`` one count or one per member).
    steps : ndarray, shape (B,)
        Angle steps per tooth (helix band height).
    coefficients : ndarray, shape (4, B)
        ``Kt`` [N/m2], ``Ke`` [1], ``Kte``, ``Kre`` [N/m] (wear already applied).
    eff : EffectParameters
        Of every member ``stock`` holds (see ``rows``).
    state : EffectState
        Tool vibration and its history of every member ``stock`` holds (the
        members ``rows`` advanced in place); ``state.angle`` is the unwrapped
        spindle angle at the start of the step (not advanced here).
    stock_top : ndarray, shape (B,)
        Stock block top [m] (highest material).
    rows : ndarray of int, shape (B,), optional
        Batch index in ``stock``, ``near``, ``eff`` and ``state`` of each
        member of the per-member arguments, when these are a subset of the
        batch (e.g. the members with an effect term on); ``None``:
        all members, in order. A member's figures do not depend on the other
        members passed with it.
    feed : ndarray, shape (B, 2), optional
        Nominal feed per tooth vector, m, as :func:`.kernel.cut_step` (the tooth-period chord).
    back : ndarray, shape (B, >= passes, 2), optional
        Tool-centre displacement over the last ``i + 1`` tooth periods (row ``i``), m
        (:func:`.kernel.chords_back_all`; row 0 must be ``feed``); default: ``(i + 1)`` times the feed
        (a constant feed).

    Returns
    -------
    StepResult
        Shapes (B, ...) with B = ``p_old.shape[0]``.
    """
    B = p_old.shape[0]
    R = radius
    if rows is None:
        rows = np.arange(B)
    else:
        rows = np.asarray(rows, dtype=np.int64)
        eff = _members(eff, rows)
    ns = substep_counts(n, B)
    dp, nmax, pitch, centre, theta, feed = step_kinematics(p_old, p_new, theta0, omega, h, ns, flutes, feed)
    K = theta.shape[1] - 1
    # instants and substeps of each member (beyond its own count: not evaluated, no contribution)
    inst_ok = np.arange(K + 1)[None, :] <= ns[:, None]  # (B, K+1)
    sub_ok = (np.arange(K)[None, :] < ns[:, None])[:, :, None]  # (B, K, 1)
    height = stock_top - np.minimum(p_old[:, 2], p_new[:, 2])
    z_lo, z_hi, lag, _ = band_layout(eff, R, pitch, steps, height)
    nb = z_lo.shape[1]
    et = np.repeat(np.arange(nmax), nb)  # tooth of each edge
    eb = np.tile(np.arange(nb), nmax)  # band of each edge
    offset = et[None, :] * pitch[:, None] - lag[:, eb]  # (B, E)
    phi = theta[:, :, None] + offset[:, None, :]  # (B, K+1, E)
    ok = (et[None, :] < flutes[:, None]) & np.isfinite(z_lo[:, eb])  # (B, E)
    toff = eff.runout_offsets(flutes, nmax)  # (B, nmax, passes)
    off1 = np.maximum(toff[:, et, 0], 0.0)  # (B, E)
    # a tooth that stands out by runout is tested for material at its own reach (runout_reach)
    sweep, face = runout_reach(toff, eff.passes(flutes), eff.radius_offsets(flutes, nmax))
    reach = np.where(sweep[:, et] > 0.0, R[:, None] + sweep[:, et], R[:, None])  # (B, E)
    reach_stock = np.where(sweep[:, et] > 0.0, R[:, None] + face[:, et], R[:, None])
    chatter = eff.chatter_wn > 0
    # only points that can have a chip are looked at (any point with a tool mode)
    g = feed[:, 0, None, None] * np.sin(phi) + feed[:, 1, None, None] * np.cos(phi)
    may_cut = (g + off1[:, None, :] > 0.0) | chatter[:, None, None]
    shape = phi.shape
    member = np.broadcast_to(np.arange(B)[:, None, None], shape).ravel()
    c_flat = np.broadcast_to(centre[:, :, None, :], shape + (3,)).reshape(-1, 3)
    lo_f = np.broadcast_to(z_lo[:, eb][:, None, :], shape).ravel()
    hi_f = np.broadcast_to(z_hi[:, eb][:, None, :], shape).ravel()
    active = (np.broadcast_to(ok[:, None, :], shape) & may_cut & inst_ok[:, :, None]).ravel()
    reach_f = np.broadcast_to(reach[:, None, :], shape).ravel()
    reach_sf = np.broadcast_to(reach_stock[:, None, :], shape).ravel()
    depth = _band_depth(stock, near, rows[member], c_flat, phi.ravel(), R[member], lo_f, hi_f, active,
                        reach_f, reach_sf).reshape(shape)

    inside = depth > 0.0
    change = (inside[:, :-1] ^ inside[:, 1:]) & sub_ok
    sstar = np.full((B, K, nmax * nb), np.nan)
    if np.any(change):
        bb, kk, ee = np.nonzero(change)
        e_lo = inside[bb, kk, ee]
        lo = np.zeros(bb.size)
        width = 1.0
        inner = np.arange(1, SECTIONS) / SECTIONS
        for _ in range(SECTION_ROUNDS):
            s_try = lo[:, None] + width * inner[None, :]  # (M, S-1)
            f = (kk[:, None] + s_try) / ns[bb][:, None]
            c_try = p_old[bb][:, None, :] + f[..., None] * dp[bb][:, None, :]
            phi_try = theta0[bb][:, None] + (omega[bb] * h)[:, None] * f + offset[bb, ee][:, None]
            m_try = np.broadcast_to(bb[:, None], f.shape).ravel()
            g_try = feed[bb, 0][:, None] * np.sin(phi_try) + feed[bb, 1][:, None] * np.cos(phi_try)
            act = ((g_try + off1[bb, ee][:, None] > 0.0) | chatter[bb][:, None]).ravel()
            e_try = _band_depth(stock, near, rows[m_try], c_try.reshape(-1, 3), phi_try.ravel(), R[m_try],
                                np.broadcast_to(z_lo[bb, eb[ee]][:, None], f.shape).ravel(),
                                np.broadcast_to(z_hi[bb, eb[ee]][:, None], f.shape).ravel(),
                                act, np.broadcast_to(reach[bb, ee][:, None], f.shape).ravel(),
                                np.broadcast_to(reach_stock[bb, ee][:, None], f.shape).ravel()).reshape(f.shape) > 0.0
            flipped = e_try != e_lo[:, None]
            first = np.where(flipped.any(axis=1), flipped.argmax(axis=1), SECTIONS - 1)
            lo = lo + width * first / SECTIONS
            width /= SECTIONS
        sstar[bb, kk, ee] = lo + 0.5 * width

    force = np.zeros((B, 2))
    peak = np.zeros(B)
    mean = np.zeros((B, 4))
    axial = np.zeros(B)
    chip = np.zeros(B)
    engaged = np.zeros(B, dtype=np.int64)
    gap = pitch / HISTORY_PER_PITCH
    passes = eff.passes(flutes)
    if back is None:
        back = np.arange(1, MAX_PASSES + 1)[None, :, None] * feed[:, None, :]
    back = np.ascontiguousarray(back, dtype=np.float64)
    if back.shape[0] != B or back.shape[1] < passes.max() or back.shape[2] != 2:
        raise CncTwinError(f"cut_step_effects: back has shape {back.shape}; expected ({B}, >= {passes.max()}, 2)")
    _integrate(
        h, ns, omega, state.angle, feed, back, R, pitch, coefficients, eff.stiffness, toff, passes, et, nmax,
        phi, depth, sstar,
        eff.chatter_wn, eff.chatter_zeta, eff.chatter_k, rows, state.mode, state.ht, state.hx, state.hy, state.meta,
        gap, force, peak, mean, axial, chip, engaged,
    )
    return StepResult(force=force, fc_peak=peak, mean=mean, axial_depth=axial, chip_thickness=chip,
                      engaged_teeth=engaged)


def _members(eff: EffectParameters, rows: np.ndarray) -> EffectParameters:
    """The effect parameters of the members ``rows`` (arrays of shape (len(rows),))."""
    return EffectParameters(**{f.name: getattr(eff, f.name)[rows] for f in dataclasses.fields(eff)})


@njit
def _piece(phi: np.ndarray, depth: np.ndarray, sstar: np.ndarray, m: int, k: int,
           e: int) -> tuple[float, float, float, float]:
    """Engaged piece of edge ``e`` in substep ``k``: ``(lo, hi, depth, weight)``; weight 0 when none."""
    d0 = depth[m, k, e]
    d1 = depth[m, k + 1, e]
    p0 = phi[m, k, e]
    p1 = phi[m, k + 1, e]
    if d0 > 0.0 and d1 > 0.0:
        return p0, p1, 0.5 * (d0 + d1), 1.0
    s = sstar[m, k, e]
    if not math.isnan(s):
        ps = p0 + s * (p1 - p0)
        if d0 > 0.0:
            return p0, ps, d0, s
        return ps, p1, d1, 1.0 - s
    return 0.0, 0.0, 0.0, 0.0


@njit
def _depth_at(depth: np.ndarray, sstar: np.ndarray, m: int, k: int, e: int, s: float) -> float:
    """Axial depth of edge ``e`` at fraction ``s`` of substep ``k`` (engaged side at a located change)."""
    d0 = depth[m, k, e]
    d1 = depth[m, k + 1, e]
    if d0 > 0.0 and d1 > 0.0:
        return d0 + s * (d1 - d0)
    st = sstar[m, k, e]
    if math.isnan(st):
        return d1 if s >= 1.0 else (d0 if s <= 0.0 else 0.0)
    if d0 > 0.0 and s <= st:
        return d0
    if d1 > 0.0 and s >= st:
        return d1
    return 0.0


@njit
def _instant(
    m: int, k: int, s: float, forms: np.ndarray, nf: int, phi: np.ndarray, depth: np.ndarray, sstar: np.ndarray,
    back: np.ndarray, dq: np.ndarray, toff: np.ndarray, et: np.ndarray, kt: float, ke: float, kte: float,
    kre: float, stiff: float, dsum: np.ndarray, wd: np.ndarray, wh: np.ndarray,
) -> tuple[float, float, float, float, int]:
    """Force on the tool at fraction ``s`` of substep ``k``; also largest tooth depth, chip, engaged teeth.

    ``back`` holds the member's tool-centre displacements over the last tooth periods
    (:func:`.chip.build_forms`), ``dq`` the regenerative displacements at that instant; ``forms`` is work space.
    """
    ne = phi.shape[2]
    dsum[:] = 0.0
    for e in range(ne):
        d = _depth_at(depth, sstar, m, k, e, s)
        wd[e] = d
        wh[e] = 0.0
        if d > 0.0:
            p = phi[m, k, e] + s * (phi[m, k + 1, e] - phi[m, k, e])
            build_forms(forms, nf, back, dq, toff[m, et[e]])
            wh[e] = chip_now(forms, nf, 1.0, 0.0, p)
            if wh[e] > 0.0:
                dsum[et[e]] += d
    fx = 0.0
    fy = 0.0
    hmax = 0.0
    for e in range(ne):
        d = wd[e]
        if not (d > 0.0 and wh[e] > 0.0):
            wd[e] = 0.0
            continue
        alpha, beta = deflection_factors(kt, ke, kre, dsum[et[e]], stiff)
        hc = alpha * wh[e] - beta
        if not hc > 0.0:
            wd[e] = 0.0
            continue
        p = phi[m, k, e] + s * (phi[m, k + 1, e] - phi[m, k, e])
        a, b, _ = edge_force_on_tool(kt, ke, kte, kre, d, hc, p)
        fx += a
        fy += b
        hmax = max(hmax, hc)
    # engaged teeth and their depth (bands with a positive chip)
    dsum[:] = 0.0
    for e in range(ne):
        dsum[et[e]] += wd[e]
    dmax = 0.0
    n_in = 0
    for j in range(dsum.shape[0]):
        if dsum[j] > 0.0:
            n_in += 1
            dmax = max(dmax, dsum[j])
    return fx, fy, dmax, hmax, n_in


@njit
def _integrate(
    h: float, ns: np.ndarray, omega: np.ndarray, angle: np.ndarray, feed: np.ndarray, back: np.ndarray,
    radius: np.ndarray,
    pitch: np.ndarray, coef: np.ndarray, stiffness: np.ndarray, toff: np.ndarray, passes: np.ndarray,
    et: np.ndarray, nmax: int, phi: np.ndarray, depth: np.ndarray, sstar: np.ndarray, wn: np.ndarray,
    zeta: np.ndarray, kc: np.ndarray, rows: np.ndarray, mode: np.ndarray, ht: np.ndarray, hx: np.ndarray,
    hy: np.ndarray, meta: np.ndarray, gap: np.ndarray, out_force: np.ndarray, out_peak: np.ndarray,
    out_mean: np.ndarray, out_depth: np.ndarray, out_chip: np.ndarray, out_eng: np.ndarray,
) -> None:
    """Sequential part of :func:`cut_step_effects` (means, instants, peak, tool mode), per member.

    Member ``m`` has ``ns[m]`` substeps and is row ``rows[m]`` of the state
    arrays (``angle``, ``mode``, ``ht``, ``hx``, ``hy``, ``meta``); ``back[m]`` its tool-centre
    displacements over the last tooth periods (:func:`.chip.build_forms`).
    """
    B = phi.shape[0]
    ne = phi.shape[2]
    acc, sub, tmp, cuts, forms, dq, dtooth, dsum = effect_workspace(nmax)
    wd = np.zeros(ne)
    wh = np.zeros(ne)
    for m in range(B):
        g = rows[m]
        om = omega[m]
        n = ns[m]
        dt = h / n
        span = om * h / n
        kt, ke, kte, kre = coef[0, m], coef[1, m], coef[2, m], coef[3, m]
        stiff = stiffness[m]
        fxt = feed[m, 0]
        fyt = feed[m, 1]
        bk = back[m]
        R = radius[m]
        nf = passes[m]
        chat = wn[m] > 0.0
        qx, qy, vx, vy = mode[g, 0], mode[g, 1], mode[g, 2], mode[g, 3]
        dq[:] = 0.0
        acc[:] = 0.0
        peak = 0.0
        for k in range(n):
            if chat:
                regenerative_displacements(dq, nf, ht, hx, hy, meta, g, angle[g] + span * (k + 0.5),
                                           qx + 0.5 * dt * vx, qy + 0.5 * dt * vy, pitch[m])
            # engaged depth of each tooth in this substep (static deflection)
            dtooth[:] = 0.0
            if stiff > 0.0:
                for e in range(ne):
                    lo, hi, d, w = _piece(phi, depth, sstar, m, k, e)
                    if w > 0.0:
                        build_forms(forms, nf, bk, dq, toff[m, et[e]])
                        if chip_now(forms, nf, 1.0, 0.0, 0.5 * (lo + hi)) > 0.0:
                            dtooth[et[e]] += d
            sub[:] = 0.0
            for e in range(ne):
                lo, hi, d, w = _piece(phi, depth, sstar, m, k, e)
                if not w > 0.0:
                    continue
                alpha, beta = deflection_factors(kt, ke, kre, dtooth[et[e]], stiff)
                build_forms(forms, nf, bk, dq, toff[m, et[e]])
                if span >= SHORT_SPAN:
                    add_piece(kt, ke, kte, kre, d, forms, nf, alpha, beta, fxt, fyt, lo, hi, R, om, 1.0 / span,
                              sub, tmp, cuts)
                else:
                    pm = 0.5 * (lo + hi)
                    add_piece_point(kt, ke, kte, kre, d, chip_now(forms, nf, alpha, beta, pm),
                                    fxt * math.sin(pm) + fyt * math.cos(pm), pm, R, om, w, sub)
            for i in range(4):
                acc[i] += sub[i]
            # entry/exit instants inside the substep (engaged side)
            for e in range(ne):
                st = sstar[m, k, e]
                if not math.isnan(st):
                    fx, fy, _, _, _ = _instant(m, k, st, forms, nf, phi, depth, sstar, bk, dq, toff, et, kt,
                                               ke, kte, kre, stiff, dsum, wd, wh)
                    peak = max(peak, math.sqrt(fx * fx + fy * fy))
            if chat:
                qx, vx = mode_advance(qx, vx, sub[0], wn[m], zeta[m], kc[m], dt)
                qy, vy = mode_advance(qy, vy, sub[1], wn[m], zeta[m], kc[m], dt)
                theta1 = angle[g] + span * (k + 1)
                history_push(ht, hx, hy, meta, g, theta1, qx, qy, gap[m])
                regenerative_displacements(dq, nf, ht, hx, hy, meta, g, theta1, qx, qy, pitch[m])
            fx, fy, dm, hm, ni = _instant(m, k, 1.0, forms, nf, phi, depth, sstar, bk, dq, toff, et, kt, ke,
                                          kte, kre, stiff, dsum, wd, wh)
            peak = max(peak, math.sqrt(fx * fx + fy * fy))
            if k == n - 1:
                out_force[m, 0] = fx
                out_force[m, 1] = fy
                out_depth[m] = dm
                out_chip[m] = hm
                out_eng[m] = ni
        for i in range(4):
            out_mean[m, i] = acc[i] / n
        out_peak[m] = peak
        mode[g, 0], mode[g, 1], mode[g, 2], mode[g, 3] = qx, qy, vx, vy


# the cached step links the chip kernels' code: recompile it when their modules change
guard_cache(_integrate, chip, effect_model)
