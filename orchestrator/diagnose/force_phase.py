"""A dynamometer's clock refined with the twin's forces replayed at the recorded sample instants.

A dynamometer without an anti-alias filter that samples a 2-flute tool at 6000 rpm every 1 ms sees every
tooth at the same five angles: a narrow pulse (a 1 mm side pass: 0.7 ms of each 5 ms tooth period) is caught
or missed for whole cuts, and where a cut's engaged arc grows from nothing (the tool reaching the block's
face) its first pulses show only once the arc covers one of those angles. Moving means of ``|F|``
(:func:`.align.force_clock`) cannot tell that sampling from the clock, nor the machine's tooth phase at a
cut's entry from the twin's: 2-5 ms (up to 19 ms) of clock error on :mod:`.scorecard_part`'s short part.

Here the twin's cutting component is replayed along the twin's tool path at the recorded instants (program
clock ``t - offset``) and compared with the recorded ``fx``, ``fy`` sample by sample, the spindle angle
free: a clock error ``d`` moves the pulses by ``omega d``, which the angle takes up, and the tool path by
``v d``, which it cannot. Per cut a scale, the changes by a radial/tangential ratio and by edge forces, and
an offset per channel are fitted (what the cutting diagnosis names later must not pull the clock). Once
the cutting diagnosis has fitted its effects, the clock can be refined again on a replay with them
(``effects``: a runout gives the teeth unequal chips, which a replay without it fits with a biased offset).

Cost: only the recorded cuts enter the misfit, so only they are replayed, each from two envelope windows
(4 spindle revolutions) before it, cut into one piece per core that run side by side (each piece again with
that history); the edge-force members run the effect kernel in a call of their own, the others the plain
kernel. Checked once per clock against the whole replay at the coarse offset (the whole replay is used when
they differ, or when wear or spindle droop make the state depend on all that came before).
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import numpy as np

from fmus_src.cutting.table import EngagementTable
from fmus_src.threads import usable_cores

from ..case import Case
from ..machine import Machine
from ..recording import Recording
from ..twin import cutting_parameters
from .align import _affine_misfit, cut_groups, cutting_indicator, load_envelope
from .cutting_replay import ForceInputs, run_force_replay, step_speeds
from .cutting_table import one_cutter_table

#: Force shapes replayed per spindle angle: baseline, radial/tangential ratio, tangential and radial edge force.
SHAPES = ("baseline", "ke", "kte", "kre")
#: Half-width of the clock shifts searched around the coarse offset, s.
SPAN_S = 20e-3
#: Offset step of the scans, s.
COARSE_STEP_S = 1e-3
#: Spindle angle steps of the scans, rad (1 degree: a tooth pulse a degree off is many newtons off).
ANGLE_STEP_RAD = math.radians(1.0)
#: Angles tried at each offset of the outward scan, about the neighbouring offset's best.
TRACK_ANGLES = 5
#: Shapes of the wide scan (baseline and radial/tangential ratio: the fast kernel).
CHEAP_SHAPES = 2
#: Half-width of the scan with every shape about the wide scan's best, s.
REFINE_SPAN_S = 2e-3
#: Most replays of the final simplex search.
SIMPLEX_EVALUATIONS = 40
#: Replayed time before each recorded cut, in envelope windows (``window_s``: 2 spindle revolutions), enough
#: for the chip's last tooth period and a revolution of surfaces (runout).
HISTORY_WINDOWS = 2.0
#: Largest difference of the pieced replay from the whole replay at the coarse offset, relative to the largest
#: force; above it (a path that passes the same place twice, a state the pieces cannot start from) the
#: whole replay is used.
PIECE_TOLERANCE = 1e-6


def _twin_inputs(twin: Recording, t_prog: np.ndarray) -> ForceInputs:
    """The twin's tool path [m] and spindle speed [rad/s] at program times ``t_prog``."""
    t_twin = np.asarray(twin.t, float)
    pos = np.column_stack([np.interp(t_prog, t_twin, np.asarray(twin[f"{a}_mm"], float)) * 1e-3 for a in "xyz"])
    rpm = np.interp(t_prog, t_twin, np.asarray(twin["spindle_rpm"], float))
    return ForceInputs(np.asarray(t_prog, float), pos, np.maximum(rpm, 0.0) * 2.0 * math.pi / 60.0,
                       "twin spindle_rpm")


def _cut_misfits(fx: np.ndarray, fy: np.ndarray, rx: np.ndarray, ry: np.ndarray,
                 groups: list[np.ndarray], shapes: int) -> np.ndarray:
    """Sum of squares [N²] of the recorded ``fx``, ``fy`` about each angle's shapes, fitted per cut.

    ``rx``, ``ry`` hold :data:`SHAPES` members per angle: the baseline and the changes by a radial/tangential
    ratio, a tangential and a radial edge force. Per cut, the recorded forces are fitted by a scale of the
    baseline (wear, a ``Kt`` error), those changes (what the cutting diagnosis will name later must not pull
    the clock) and an offset per channel (a dynamometer drifts); ``shapes`` of them per angle. Returns shape
    (B // shapes,).
    """
    n_angles = rx.shape[1] // shapes
    total = np.zeros(n_angles)
    for g in groups:
        b = np.r_[fx[g], fy[g]]
        ones, zeros = np.ones(g.size), np.zeros(g.size)
        for j in range(n_angles):
            cols = [np.r_[rx[g, shapes * j], ry[g, shapes * j]]]
            for m in range(1, shapes):
                i = shapes * j + m
                cols.append(np.r_[rx[g, i], ry[g, i]] - cols[0])
            a = np.column_stack([*cols, np.r_[ones, zeros], np.r_[zeros, ones]])
            coef, *_ = np.linalg.lstsq(a, b, rcond=None)
            r = b - a @ coef
            total[j] += float(r @ r)
    return total


def _windows(t: np.ndarray, groups: list[np.ndarray], history_s: float) -> list[tuple[int, int]]:
    """Sample ranges ``[a, b)`` replayed: each cut group from ``history_s`` before it, overlapping ones merged."""
    spans = sorted((int(np.searchsorted(t, t[int(g.min())] - history_s)), int(g.max()) + 1) for g in groups)
    merged: list[list[int]] = []
    for a, b in spans:
        if merged and a <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], b)
        else:
            merged.append([a, b])
    return [(a, b) for a, b in merged]


def _pieces(t: np.ndarray, windows: list[tuple[int, int]], history_s: float,
            count: int) -> list[tuple[int, int, int]]:
    """The windows cut into about ``count`` pieces ``(a, keep, b)`` of equal length, to replay side by side.

    Piece ``(a, keep, b)`` replays samples ``a .. b - 1`` and keeps ``keep .. b - 1``: a piece cut out of a
    window starts ``history_s`` before the samples it keeps.
    """
    length = -(-sum(b - a for a, b in windows) // max(count, 1))
    out = []
    for a, b in windows:
        for keep in range(a, b, max(length, 1)):
            start = a if keep == a else min(int(np.searchsorted(t, t[keep] - history_s)), keep)
            out.append((max(start, a), keep, min(keep + length, b)))
    return out


class _Replayer:
    """The twin's forces at the recorded instants for (offset, spindle angle) pairs, replayed in windows.

    Only the samples of the recorded cuts enter the misfit, so only they and ``history_s`` before each cut
    (the chip's last tooth period, a revolution of surfaces for runout) are replayed: each window's
    component is set up at its first sample with the spindle angle the whole replay would have there.

    Parameters
    ----------
    case : Case
        With the twin's machine.
    table : EngagementTable
    twin : Recording
        The twin's run (program clock).
    t_rec : ndarray, shape (n,)
        Recorded sample times [s].
    groups : list of ndarray
        Sample indices of the recorded cuts.
    ref : int
        Sample at which the angles are given.
    history_s : float
        Replayed time before each cut, s.
    effects : mapping, optional
        Cutting-component parameter values (SI, :func:`.cutting_library.component_values`) of every member:
        the effects the cutting diagnosis fitted. An edge-force shape adds its 1e4 N/m to the fitted value.
    """

    def __init__(self, case: Case, table: EngagementTable, twin: Recording, t_rec: np.ndarray,
                 groups: list[np.ndarray], ref: int, history_s: float,
                 effects: Mapping[str, float] | None = None) -> None:
        self.case, self.table, self.twin, self.t_rec, self.ref = case, table, twin, t_rec, ref
        params = cutting_parameters(case)
        ke = float(params.get("ke", 0.5))
        base = {k: float(v) for k, v in (effects or {}).items()}
        shapes = [{}, {"ke": 1.2 * ke}, {"edge_force_tangential": 1e4}, {"edge_force_radial": 1e4}]
        self.shapes = [{**base, **{k: base.get(k, 0.0) + v if k.startswith("edge_force") else v
                                   for k, v in shape.items()}} for shape in shapes]
        stateful = any(float({**params, **base}.get(k, 0.0)) != 0.0 for k in ("wear_rate", "spindle_droop"))
        self.pieces = [(0, 0, t_rec.size)] if stateful else _pieces(t_rec, _windows(t_rec, groups, history_s),
                                                                   history_s, usable_cores())
        self._pool: ThreadPoolExecutor | None = None

    def whole(self) -> None:
        """Replay every sample from the first in one piece (the check of the pieces failed)."""
        self.pieces = [(0, 0, self.t_rec.size)]
        self.close()

    def forces(self, offset: float, angles: np.ndarray, shapes: int) -> tuple[np.ndarray, np.ndarray]:
        """``fx``, ``fy`` [N], shape (n, len(angles) * shapes): ``shapes`` of the shapes per angle, 0 outside pieces.

        ``angles`` are the spindle angle of tooth 0 at sample ``ref`` [rad]. The pieces run side by side in
        threads (the compiled replay releases the GIL).
        """
        inputs = _twin_inputs(self.twin, self.t_rec - offset)
        turned = np.r_[0.0, np.cumsum(step_speeds(inputs) * np.diff(inputs.t))]   # spindle angle from sample 0
        members = [shape for _ in angles for shape in self.shapes[:shapes]]
        n = self.t_rec.size
        fx, fy = np.zeros((n, len(members))), np.zeros((n, len(members)))

        # the edge-force members need the effect kernel; the others run apart on the plain one (the same
        # forces to 1e-13 N, several times cheaper)
        kinds = [list(range(min(shapes, CHEAP_SHAPES))), list(range(CHEAP_SHAPES, shapes))]
        calls = [[(j * shapes + i) for j in range(len(angles)) for i in kind] for kind in kinds if kind]

        def piece(a: int, keep: int, b: int) -> None:
            window = ForceInputs(inputs.t[a:b], inputs.position[a:b], inputs.omega[a:b], inputs.omega_source)
            theta = angles - (turned[self.ref] - turned[a])
            for cols in calls:
                rep = run_force_replay(self.case, self.table, window, [members[k] for k in cols],
                                       theta[np.asarray(cols) // shapes])
                fx[keep:b, cols], fy[keep:b, cols] = rep.fx[keep - a:], rep.fy[keep - a:]

        if len(self.pieces) == 1:
            piece(*self.pieces[0])
        else:
            if self._pool is None:
                self._pool = ThreadPoolExecutor(max_workers=len(self.pieces))
            list(self._pool.map(lambda p: piece(*p), self.pieces))
        return fx, fy

    def close(self) -> None:
        """End the threads of the pieces."""
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None


def _scan(replayer: _Replayer, fx: np.ndarray, fy: np.ndarray, groups: list[np.ndarray], offsets: np.ndarray,
          angles: np.ndarray, shapes: int = len(SHAPES)) -> np.ndarray:
    """Misfit [N²] of every (offset, angle) pair, shape (len(offsets), len(angles)).

    ``angles`` are the spindle angle of tooth 0 at the replayer's sample ``ref`` (inside a cut, the spindle at
    speed), not at the first sample, where the spindle may still be running up. ``shapes``: how many of
    :data:`SHAPES` are replayed (the edge-force members run the slower effect kernel, about 35 ms a member
    against 2 ms for the baseline over the short part's 3500 samples).
    """
    out = np.empty((offsets.size, angles.size))
    for i, o in enumerate(offsets):
        rx, ry = replayer.forces(float(o), angles, shapes)
        out[i] = _cut_misfits(fx, fy, rx, ry, groups, shapes)
    return out


def phase_matched_offset(case: Case, machine: Machine, twin: Recording, t_rec: np.ndarray, fx: np.ndarray,
                         fy: np.ndarray, coarse: float, window_s: float,
                         effects: Mapping[str, float] | None = None) -> tuple[float, float]:
    """Refine a dynamometer's clock with the twin's forces replayed at the recorded instants.

    The twin's cutting component is replayed along the twin's tool path at ``t_rec - offset``; the recorded
    ``fx``, ``fy`` are compared sample by sample (a scale per cut, an offset per channel and cut). The misfit
    is a narrow valley in (offset, spindle angle): a tooth pulse a degree off is many newtons off. So: the
    angle at ``coarse`` on a grid of :data:`ANGLE_STEP_RAD` over a tooth pitch; then offsets every
    :data:`COARSE_STEP_S` outwards within :data:`SPAN_S` of ``coarse``, each with :data:`TRACK_ANGLES`
    angles about the neighbour's best (the valley drifts in angle); then a simplex search in (offset, angle)
    from the best of those. Every replay covers only the recorded cuts and :data:`HISTORY_WINDOWS` windows
    before each (:class:`_Replayer`).

    Parameters
    ----------
    case : Case
        Tool, stock, material and program (path-mode engagement table).
    machine : Machine
        Parameter set of the twin (cutting coefficients).
    twin : Recording
        The twin's run with cutting (``x_mm``, ``y_mm``, ``z_mm``, ``spindle_rpm``), program clock.
    t_rec, fx, fy : ndarray, shape (n,)
        Recorded force sample times (logger clock) [s] and forces [N], finite.
    coarse : float
        Offset (logger minus program clock) to start from, s.
    window_s : float
        Window [s] by which the recorded cuts (:func:`.align.cut_groups`) are widened.
    effects : mapping, optional
        Cutting-component parameter values (SI) of the effects fitted by the cutting diagnosis, replayed in
        every member (:class:`_Replayer`). With a runout the teeth differ, so the first angle grid covers a
        whole revolution instead of a tooth pitch.

    Returns
    -------
    (float, float)
        Offset [s] and the misfit there [N²].
    """
    from scipy.optimize import minimize

    c = replace(case, machine=machine)
    table = one_cutter_table(c)
    t_rec = np.asarray(t_rec, float)
    y = load_envelope(t_rec, np.hypot(fx, fy), window_s)(t_rec)
    groups = cut_groups(t_rec, cutting_indicator(y) > 0.5, window_s) or [np.arange(t_rec.size)]
    longest = max(groups, key=len)
    ref = int(longest[longest.size // 2])
    pitch = 2.0 * math.pi / max(int(c.tool.flutes), 1)
    if float((effects or {}).get("runout_eccentricity", 0.0)) > 0.0:
        pitch = 2.0 * math.pi   # the teeth differ: the angle of tooth 0 is searched over a whole revolution

    replayer = _Replayer(c, table, twin, t_rec, groups, ref, HISTORY_WINDOWS * window_s, effects)
    try:
        if replayer.pieces != [(0, 0, t_rec.size)]:   # they must give the whole replay's forces where it looks
            rows = np.concatenate(groups)
            whole = _Replayer(c, table, twin, t_rec, groups, ref, 0.0, effects)
            whole.whole()
            checks = [r.forces(coarse, np.zeros(1), len(SHAPES)) for r in (replayer, whole)]
            worst = max(float(np.max(np.abs(checks[0][i][rows] - checks[1][i][rows]))) for i in range(2))
            peak = max(float(np.max(np.abs(checks[1][i][rows]))) for i in range(2))
            if not worst <= PIECE_TOLERANCE * peak + 1e-9:
                replayer.whole()

        def scan(offset: float, angles: np.ndarray, shapes: int) -> np.ndarray:
            return _scan(replayer, fx, fy, groups, np.array([offset]), angles, shapes)[0]

        def track(centre: float, angle: float, steps: int, shapes: int) -> dict[int, tuple[float, float]]:
            """Best (misfit, angle) at offsets ``centre + i COARSE_STEP_S``, |i| <= steps, angles tracked outwards."""
            window = (np.arange(TRACK_ANGLES) - TRACK_ANGLES // 2) * ANGLE_STEP_RAD
            found: dict[int, tuple[float, float]] = {}
            for direction in (-1, 1):
                for i in range(0 if direction < 0 else 1, steps + 1):
                    centre_angle = angle if i == 0 else found[direction * (i - 1)][1]
                    trial = centre_angle + window
                    row = scan(centre + direction * i * COARSE_STEP_S, trial, shapes)
                    k = int(np.argmin(row))
                    found[direction * i] = (float(row[k]), float(trial[k]))
            return found

        angles = np.arange(0.0, pitch, ANGLE_STEP_RAD)
        row = scan(coarse, angles, CHEAP_SHAPES)
        found = track(coarse, float(angles[int(np.argmin(row))]), int(round(SPAN_S / COARSE_STEP_S)), CHEAP_SHAPES)
        i0 = min(found, key=lambda i: found[i][0])
        centre = coarse + i0 * COARSE_STEP_S
        found = track(centre, found[i0][1], int(round(REFINE_SPAN_S / COARSE_STEP_S)), len(SHAPES))
        i0 = min(found, key=lambda i: found[i][0])
        scale = np.array([COARSE_STEP_S, ANGLE_STEP_RAD])

        def cost(u: np.ndarray) -> float:
            return float(scan(centre + u[0] * scale[0], np.array([u[1] * scale[1]]), len(SHAPES))[0])

        start = np.array([float(i0), found[i0][1] / scale[1]])
        res = minimize(cost, start, method="Nelder-Mead",
                       options={"xatol": 0.01, "fatol": 1e-3, "maxfev": SIMPLEX_EVALUATIONS,
                                "initial_simplex": [start, start + [0.5, 0.0], start + [0.0, 0.5]]})
        best = res.x if res.fun <= found[i0][0] else start
        return float(centre + best[0] * scale[0]), float(min(res.fun, found[i0][0]))
    finally:
        replayer.close()
