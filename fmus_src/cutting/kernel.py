"""One communication step of the cutting mechanics (pure function, batched).

Used by :class:`.component.CuttingLoad`; see its module docstring for the
time discretisation (substeps, exact interval integration, location of the
entry/exit instants, peak search).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import CncTwinError
from ..jit import njit, njit_borrowed
from .engagement import NearField, tooth_depth
from .force import chip_thickness, interval_mean_quantities, tooth_quantities
from .stock import ZMapStock

#: Spindle speed below which the tooth period is taken at this speed, rad/s (keeps the kernels finite;
#: a step that cuts with the spindle stopped is refused as a crash, :func:`stalled_cut`).
OMEGA_FLOOR = 1e-3
#: Entry/exit location inside a substep: rounds of equal sections (16**3 = 4096 parts).
SECTIONS = 16
SECTION_ROUNDS = 3


@dataclass(frozen=True)
class StepResult:
    """Outputs of :func:`cut_step` (forces on the **tool**).

    Attributes
    ----------
    force : ndarray, shape (B, 2)
        Force on the tool at the end of the step, N.
    fc_peak : ndarray, shape (B,)
        Largest cutting load within the step, N.
    mean : ndarray, shape (B, 4)
        Step means of Fx, Fy on the tool (N), torque (N.m), removal rate (m3/s).
    axial_depth, chip_thickness : ndarray, shape (B,)
        Largest over teeth in material at the end of the step, m.
    engaged_teeth : ndarray of int, shape (B,)
        Teeth in material with a positive chip at the end of the step.
    """

    force: np.ndarray
    fc_peak: np.ndarray
    mean: np.ndarray
    axial_depth: np.ndarray
    chip_thickness: np.ndarray
    engaged_teeth: np.ndarray


#: Spindle speed below which the spindle counts as stopped, rad/s (1 rpm). A tooth of a 2 to 4 flute
#: tool then passes every 15 to 30 s, so any feed of 1 mm/min or more gives at least 0.25 mm per tooth,
#: above any end mill's chip load (0.01 to 0.2 mm): the tool cannot cut, it pushes (a crash). The
#: spindle ramp (default 4000 rpm/s) crosses 0 .. 1 rpm in 0.25 ms, less than a step.
OMEGA_STOPPED = 2.0 * math.pi / 60.0


@njit
def stalled_cut(omega: float, peak: float, mean_fx: float, mean_fy: float) -> bool:
    """The tool feeds into material with the spindle stopped: a crash (one member, one step).

    Both are needed: the spindle speed of the step is below :data:`OMEGA_STOPPED`,
    and the tool is in the material, some tooth with a positive chip (an XY
    feed) and a positive axial depth at an evaluated instant or over a
    substep, i.e. a non-zero peak or step-mean force (any ``Kt > 0``). The
    kernels compute such a step with the tooth period of :data:`OMEGA_FLOOR`
    (the chip per tooth of a tool that does not turn is unbounded); the
    components fail the member instead of passing its force on. A stopped
    spindle in the air, a tool at rest in material, or a plunge straight down
    (no chip in this model) is not a stalled cut.

    Parameters
    ----------
    omega : float
        Spindle speed over the step, rad/s (>= 0; a reversed spindle, M4, counts as 0).
    peak, mean_fx, mean_fy : float
        Peak cutting load and step-mean force of the step, N.

    Returns
    -------
    bool
    """
    return omega < OMEGA_STOPPED and (peak > 0.0 or mean_fx != 0.0 or mean_fy != 0.0)


#: Steps kept per member for the tooth-period chip (:func:`chord_feed`): 256 steps of the twin's 1 ms cover a
#: tooth period of 0.256 s, i.e. a 2-flute tool from 117 rpm up (1 flute: 235 rpm); a longer period (or a
#: history younger than it) falls back to the step velocity times the period.
CHIP_HISTORY_STEPS = 256
#: Layout of one member's chip history (a 1-D float array of :data:`CHIP_HISTORY_WIDTH`): the ring's newest
#: record, the number of records, then per record the step length (s) and its x, y tool move (m).
H_HEAD, H_COUNT, H_RECORDS = 0, 1, 2
CHIP_HISTORY_WIDTH = H_RECORDS + 3 * CHIP_HISTORY_STEPS


@njit_borrowed
def chord_feed(hist: np.ndarray, dpx: float, dpy: float, h: float, omega: float, flutes: int
               ) -> tuple[float, float]:
    """Feed per tooth of a step: the tool-centre displacement over the last tooth period, ``c(t+h) - c(t+h-T)``.

    A tooth cuts what the previous one left (Altintas ch. 2; Sim & Lee 2023, Eq. 10-11: the change in the
    tool-centre position over one tooth period ``T = 2 pi / (flutes omega)``). The tool moves linearly
    within each step (the kernels' motion), so the chord is the step's own move plus the moves of the
    previous steps back to ``t + h - T``, the oldest one in part. At a constant feed it is the step
    velocity times ``T`` (to rounding); where the feed changes within ``T`` (a deceleration at the end of a
    cut, an acceleration out of a corner) it differs from it by ``a T (T - h) / 2``.

    Parameters
    ----------
    hist : ndarray, shape (CHIP_HISTORY_WIDTH,)
        The member's history of the previous steps (:func:`chord_advance`).
    dpx, dpy : float
        Tool move over this step, m.
    h : float
        Step length, s.
    omega : float
        Spindle speed of the step, rad/s (>= 0; below :data:`OMEGA_FLOOR` the period at that speed).
    flutes : int
        Teeth.

    Returns
    -------
    fx, fy : float
        Feed per tooth vector, m: the step velocity times ``T`` (``dp / h * T``, the same operations as
        :func:`step_kinematics`) when ``T <= h`` (the chord lies within the step: the same thing), when
        there is no history, or when the history does not reach back ``T``.
    """
    period = 2.0 * math.pi / (np.float64(flutes) * max(omega, OMEGA_FLOOR))
    fx = dpx / h * period
    fy = dpy / h * period
    rem = period - h
    if not rem > 0.0:
        return fx, fy
    cap = (hist.shape[0] - H_RECORDS) // 3
    idx = int(hist[H_HEAD])
    cx = dpx
    cy = dpy
    for _ in range(int(hist[H_COUNT])):
        r = H_RECORDS + 3 * idx
        hj = hist[r]
        if rem <= hj:
            f = rem / hj
            return cx + hist[r + 1] * f, cy + hist[r + 2] * f
        cx += hist[r + 1]
        cy += hist[r + 2]
        rem -= hj
        idx = idx - 1 if idx > 0 else cap - 1
    return fx, fy


@njit_borrowed
def chords_back(hist: np.ndarray, dpx: float, dpy: float, h: float, omega: float, flutes: int, fx: float,
                fy: float, nf: int, back: np.ndarray) -> None:
    """Tool-centre displacements over the last ``1 .. nf`` tooth periods, ``c(t+h) - c(t+h-(i+1) T)``, in place.

    The surface a tooth cuts was left ``i + 1`` tooth periods back (runout: a tooth that stands back leaves the
    older surface in place; chatter: a tooth that jumped out of the cut), where the tool centre was then; the
    chip against it is the displacement since (the independent truth's ``c(t) - c(t - i T)``). Read from the
    same record of the steps as :func:`chord_feed`, the tool moving linearly within each step.

    Parameters
    ----------
    hist : ndarray, shape (CHIP_HISTORY_WIDTH,)
        The member's history of the previous steps (:func:`chord_advance`).
    dpx, dpy : float
        Tool move over this step, m.
    h : float
        Step length, s.
    omega : float
        Spindle speed of the step, rad/s (below :data:`OMEGA_FLOOR` the period at that speed).
    flutes : int
        Teeth.
    fx, fy : float
        The step's feed per tooth (:func:`chord_feed`), m: ``back[0]`` bit for bit.
    nf : int
        Periods wanted (``1 <= nf <= back.shape[0]``).
    back : ndarray, shape (>= nf, 2)
        Written: row ``i`` the displacement over ``i + 1`` periods, m.

    Notes
    -----
    Row ``i >= 1`` falls back to the chord rule ``(i + 1) (fx, fy)`` (a constant feed over the ``i + 1``
    periods; the same operations as the kernels used before, so bit for bit) when ``(i + 1) T <= h`` (the
    span lies within the step: the same thing to rounding), and when the record does not reach back
    ``(i + 1) T``: at the start of a run, after a step with the spindle stopped or a member held, and when
    ``(i + 1) T`` exceeds :data:`CHIP_HISTORY_STEPS` steps. At a constant feed every row equals the chord
    rule to rounding (1e-12 relative).
    """
    back[0, 0] = fx
    back[0, 1] = fy
    for i in range(1, nf):
        back[i, 0] = (i + 1) * fx
        back[i, 1] = (i + 1) * fy
    if nf < 2:
        return
    period = 2.0 * math.pi / (np.float64(flutes) * max(omega, OMEGA_FLOOR))
    cap = (hist.shape[0] - H_RECORDS) // 3
    idx = int(hist[H_HEAD])  # the newest record not yet added in full
    left = int(hist[H_COUNT])  # records not yet added in full
    cx = dpx  # the step's move plus the records added in full, m
    cy = dpy
    done = 0.0  # their time, s (the step's own excluded)
    for i in range(1, nf):
        rem = (i + 1) * period - h  # how far the span reaches back beyond the step, s
        if not rem > 0.0:
            continue
        while left > 0:  # as chord_feed: add whole records until the one holding t + h - (i + 1) T
            r = H_RECORDS + 3 * idx
            if rem - done <= hist[r]:
                break
            cx += hist[r + 1]
            cy += hist[r + 2]
            done += hist[r]
            left -= 1
            idx = idx - 1 if idx > 0 else cap - 1
        if left == 0:
            return  # the record ends before: this row and the older ones keep the chord rule
        r = H_RECORDS + 3 * idx
        f = (rem - done) / hist[r]
        back[i, 0] = cx + hist[r + 1] * f
        back[i, 1] = cy + hist[r + 2] * f


@njit
def chords_back_all(hist: np.ndarray, dp: np.ndarray, h: float, omega: np.ndarray, flutes: np.ndarray,
                    feed: np.ndarray, nf: np.ndarray, back: np.ndarray) -> None:
    """:func:`chords_back` of every member, in place.

    ``hist`` (B, CHIP_HISTORY_WIDTH), ``dp`` (B, >= 2) m, ``omega`` rad/s, ``flutes``, ``feed`` (B, 2) m
    (:func:`chord_feeds`), ``nf`` (B,) periods wanted; ``back`` (B, >= max(nf), 2) m is written.
    """
    for b in range(dp.shape[0]):
        chords_back(hist[b], dp[b, 0], dp[b, 1], h, omega[b], flutes[b], feed[b, 0], feed[b, 1], nf[b], back[b])


@njit_borrowed
def chord_advance(hist: np.ndarray, h: float, dpx: float, dpy: float, omega: float) -> None:
    """Record a step that was cut (length ``h`` s, move ``dpx, dpy`` m) in a member's history, in place.

    A step with the spindle below :data:`OMEGA_STOPPED` clears the history instead: after the spindle
    starts, the chip is the step velocity times the period until the history spans a tooth period.
    """
    if not omega >= OMEGA_STOPPED:
        hist[H_COUNT] = 0.0
        return
    cap = (hist.shape[0] - H_RECORDS) // 3
    idx = int(hist[H_HEAD]) + 1
    if idx >= cap:
        idx = 0
    hist[H_HEAD] = idx
    r = H_RECORDS + 3 * idx
    hist[r] = h
    hist[r + 1] = dpx
    hist[r + 2] = dpy
    if hist[H_COUNT] < cap:
        hist[H_COUNT] += 1.0


@njit
def chord_feeds(hist: np.ndarray, dp: np.ndarray, h: float, omega: np.ndarray, flutes: np.ndarray) -> np.ndarray:
    """:func:`chord_feed` of every member: ``hist`` (B, CHIP_HISTORY_WIDTH), ``dp`` (B, >= 2) m, ``omega``,
    ``flutes`` (B,); returns the feed per tooth, shape (B, 2), m."""
    feed = np.empty((dp.shape[0], 2))
    for b in range(dp.shape[0]):
        feed[b, 0], feed[b, 1] = chord_feed(hist[b], dp[b, 0], dp[b, 1], h, omega[b], flutes[b])
    return feed


@njit
def chord_advance_all(hist: np.ndarray, h: float, dp: np.ndarray, omega: np.ndarray, held: np.ndarray) -> None:
    """:func:`chord_advance` of every member; the members ``held`` (not cut this step) have their history cleared."""
    for b in range(dp.shape[0]):
        if held[b]:
            hist[b, H_COUNT] = 0.0
        else:
            chord_advance(hist[b], h, dp[b, 0], dp[b, 1], omega[b])


def stalled_cuts(omega: np.ndarray, peak: np.ndarray, mean_fx: np.ndarray, mean_fy: np.ndarray) -> np.ndarray:
    """:func:`stalled_cut` of every member, shape (B,) bool; arguments of shape (B,)."""
    return (omega < OMEGA_STOPPED) & ((peak > 0.0) | (mean_fx != 0.0) | (mean_fy != 0.0))


def substep_counts(n: int | np.ndarray, batch: int) -> np.ndarray:
    """Substeps per member, shape (batch,) int64, from one count or one per member (each >= 1)."""
    ns = np.array(np.broadcast_to(np.asarray(n, dtype=np.int64), (batch,)))
    if ns.size and ns.min() < 1:
        raise CncTwinError(f"cutting kernel: substep counts must be integers >= 1, got {ns.min()}")
    return ns


def step_kinematics(
    p_old: np.ndarray, p_new: np.ndarray, theta0: np.ndarray, omega: np.ndarray, h: float, n: np.ndarray,
    flutes: np.ndarray, feed: np.ndarray | None = None,
) -> tuple[np.ndarray, int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Tool motion over a step of ``n`` substeps (linear move, constant spindle speed); arguments as :func:`cut_step`.

    ``n`` is per member, shape (B,) (:func:`substep_counts`); with ``K = max(n)``
    the instants ``k > n[b]`` of member ``b`` repeat its end of step (``k / n = 1``),
    the others are ``t + k h / n[b]`` exactly as for a batch of that member alone.

    Returns
    -------
    dp : ndarray, shape (B, 3)
        Move over the step, m.
    nmax : int
        Most teeth of a member.
    pitch : ndarray, shape (B,)
        Tooth pitch, rad.
    centre : ndarray, shape (B, K + 1, 3)
        Tool tip at the instants ``t + k h / n``, m.
    theta : ndarray, shape (B, K + 1)
        Spindle angle (tooth 0) at those instants, rad.
    feed : ndarray, shape (B, 2)
        Feed per tooth vector, m: the argument ``feed`` when given (the tooth-period chord,
        :func:`chord_feeds`), else the tool-centre velocity over the step times the tooth period.
    """
    dp = p_new - p_old
    nmax = int(flutes.max())
    pitch = 2.0 * math.pi / flutes
    k = np.arange(int(n.max()) + 1)
    frac = np.minimum(k[None, :], n[:, None]) / n[:, None]  # (B, K+1)
    centre = p_old[:, None, :] + frac[:, :, None] * dp[:, None, :]  # (B, K+1, 3)
    theta = theta0[:, None] + (omega * h)[:, None] * frac  # (B, K+1)
    if feed is None:
        period = 2.0 * math.pi / (flutes * np.maximum(omega, OMEGA_FLOOR))
        feed = dp[:, :2] / h * period[:, None]  # (B, 2)
    return dp, nmax, pitch, centre, theta, feed


def cut_step(
    stock: ZMapStock, near: NearField, p_old: np.ndarray, p_new: np.ndarray, theta0: np.ndarray,
    omega: np.ndarray, h: float, n: int | np.ndarray, radius: np.ndarray, flutes: np.ndarray, kt: np.ndarray,
    ke: np.ndarray, rows: np.ndarray | None = None, feed: np.ndarray | None = None,
) -> StepResult:
    """Cutting forces while the tool moves linearly from ``p_old`` to ``p_new`` in ``h`` seconds.

    Parameters
    ----------
    stock : ZMapStock
        Committed material (not modified).
    near : NearField
        Recent sweep up to the last stored path point.
    p_old, p_new : ndarray, shape (B, 3)
        Tool-tip position at the start and end of the step, m.
    theta0 : ndarray, shape (B,)
        Spindle angle (tooth 0) at the start of the step, rad.
    omega : ndarray, shape (B,)
        Spindle speed, held over the step, rad/s (>= 0).
    h : float
        Step length, s.
    n : int or ndarray of int, shape (B,)
        Substeps, one count or one per member (the ``n + 1`` instants
        ``t + k h / n`` of each member are evaluated; a member's figures are
        those of its run alone, whatever the counts of the others).
    radius : ndarray, shape (B,)
        Tool radius, m.
    flutes : ndarray of int, shape (B,)
        Teeth per member.
    kt, ke : ndarray, shape (B,)
        Cutting coefficients, N/m2 and 1.
    rows : ndarray of int, shape (B,), optional
        Batch index in ``stock`` and ``near`` of each member of the other
        arguments, when they are a subset of the members ``stock`` and
        ``near`` hold (e.g. the members without effect terms);
        ``None``: all of them, in order. A member's figures do not depend on
        the other members passed with it.
    feed : ndarray, shape (B, 2), optional
        Feed per tooth vector of each member, m (the components pass the tooth-period chord,
        :func:`chord_feeds`); default: the step velocity times the tooth period.

    Returns
    -------
    StepResult
        Shapes (B, ...) with B = ``p_old.shape[0]``.
    """
    B = p_old.shape[0]
    R = radius
    rows = np.arange(B) if rows is None else np.asarray(rows, dtype=np.int64)
    ns = substep_counts(n, B)
    dp, nmax, pitch, centre, theta, feed = step_kinematics(p_old, p_new, theta0, omega, h, ns, flutes, feed)
    K = theta.shape[1] - 1
    # instants and substeps of each member (beyond its own count: not evaluated, no contribution)
    inst_ok = np.arange(K + 1)[None, :] <= ns[:, None]  # (B, K+1)
    sub_ok = (np.arange(K)[None, :] < ns[:, None])[:, :, None]  # (B, K, 1)
    teeth = np.arange(nmax)
    phi = theta[:, :, None] + teeth[None, None, :] * pitch[:, None, None]  # (B, K+1, N)
    tooth_ok = (teeth[None, :] < flutes[:, None])[:, None, :]
    hc = chip_thickness(feed[:, 0, None, None], feed[:, 1, None, None], phi)

    # a tooth is engaged when it is in material AND has a chip (trailing teeth are not evaluated)
    shape = phi.shape
    member = np.broadcast_to(np.arange(B)[:, None, None], shape).ravel()
    c_flat = np.broadcast_to(centre[:, :, None, :], shape + (3,)).reshape(-1, 3)
    active = (np.broadcast_to(tooth_ok, shape) & (hc > 0.0) & inst_ok[:, :, None]).ravel()
    depth = tooth_depth(stock, near, rows[member], c_flat, phi.ravel(), R[member], active).reshape(shape)

    q = tooth_quantities(kt[:, None, None], ke[:, None, None], depth, hc, phi,
                         R[:, None, None], omega[:, None, None])  # (B, K+1, N, 4)
    f_tot = q[..., :2].sum(axis=2)  # (B, K+1, 2) on the tool
    fc_samples = np.hypot(f_tot[..., 0], f_tot[..., 1])
    peak = fc_samples[:, 1:].max(axis=1)

    engaged = depth > 0.0
    both = engaged[:, :-1] & engaged[:, 1:] & sub_ok
    fx_t = feed[:, 0, None, None]
    fy_t = feed[:, 1, None, None]
    q_int = interval_mean_quantities(
        kt[:, None, None], ke[:, None, None], 0.5 * (depth[:, :-1] + depth[:, 1:]), fx_t, fy_t,
        phi[:, :-1], phi[:, 1:], R[:, None, None], omega[:, None, None],
    )  # (B, K, N, 4)
    integral = np.where(both[..., None], q_int, 0.0).sum(axis=(1, 2))  # (B, 4), in substeps
    change = (engaged[:, :-1] ^ engaged[:, 1:]) & sub_ok
    if np.any(change):
        bb, kk, jj = np.nonzero(change)
        e_lo = engaged[bb, kk, jj]
        # locate the first change of state: SECTION_ROUNDS rounds of SECTIONS equal parts each
        lo = np.zeros(bb.size)
        width = 1.0
        inner = np.arange(1, SECTIONS) / SECTIONS  # (S-1,)
        for _ in range(SECTION_ROUNDS):
            s_try = lo[:, None] + width * inner[None, :]  # (M, S-1)
            f = (kk[:, None] + s_try) / ns[bb][:, None]
            c_try = p_old[bb][:, None, :] + f[..., None] * dp[bb][:, None, :]
            phi_try = theta0[bb][:, None] + (omega[bb] * h)[:, None] * f + (jj * pitch[bb])[:, None]
            m_try = np.broadcast_to(bb[:, None], f.shape)
            h_try = chip_thickness(feed[bb, 0][:, None], feed[bb, 1][:, None], phi_try)
            e_try = tooth_depth(stock, near, rows[m_try.ravel()], c_try.reshape(-1, 3), phi_try.ravel(),
                                R[m_try.ravel()], (h_try > 0.0).ravel()).reshape(f.shape) > 0.0
            flipped = e_try != e_lo[:, None]
            first = np.where(flipped.any(axis=1), flipped.argmax(axis=1), SECTIONS - 1)  # parts kept before it
            lo = lo + width * first / SECTIONS
            width /= SECTIONS
        s_star = lo + 0.5 * width
        f = (kk + s_star) / ns[bb]
        phi_star = theta0[bb] + omega[bb] * h * f + jj * pitch[bb]
        k_eng = np.where(e_lo, kk, kk + 1)
        depth_eng = depth[bb, k_eng, jj]
        h_star = chip_thickness(feed[bb, 0], feed[bb, 1], phi_star)
        q_star = tooth_quantities(kt[bb], ke[bb], depth_eng, h_star, phi_star, R[bb], omega[bb])
        phi_a = np.where(e_lo, phi[bb, kk, jj], phi_star)
        phi_b = np.where(e_lo, phi_star, phi[bb, kk + 1, jj])
        q_part = interval_mean_quantities(
            kt[bb], ke[bb], depth_eng, feed[bb, 0], feed[bb, 1], phi_a, phi_b, R[bb], omega[bb]
        )
        length = np.where(e_lo, s_star, 1.0 - s_star)
        np.add.at(integral, bb, length[:, None] * q_part)
        others0 = f_tot[bb, kk] - q[bb, kk, jj, :2]
        others1 = f_tot[bb, kk + 1] - q[bb, kk + 1, jj, :2]
        f_b = q_star[:, :2] + (1.0 - s_star)[:, None] * others0 + s_star[:, None] * others1
        np.maximum.at(peak, bb, np.hypot(f_b[:, 0], f_b[:, 1]))
    mean = integral / ns[:, None]

    b = np.arange(B)
    in_cut = engaged[b, ns]  # (B, N) at each member's last instant
    return StepResult(
        force=f_tot[b, ns],
        fc_peak=peak,
        mean=mean,
        axial_depth=depth[b, ns].max(axis=1),
        chip_thickness=np.where(in_cut, hc[b, ns], 0.0).max(axis=1),
        engaged_teeth=in_cut.sum(axis=1),
    )
