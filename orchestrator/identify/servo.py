"""Servo identification: scale factors Spp, Svp, Svi per axis (Sim & Lee 2023, Eq. 7-9).

The closed loop (the twin's MCU and DriveAxis, :mod:`.closed_loop`) is
replayed with the **recorded** reference positions and compared with the
recorded following error ``e = ref - actual`` and current command ``Atc``.
Friction, masses and nominal gains come from the machine file (identify
friction first and pass that file).

A servo log without commands (FANUC Servo Guide style: ``{a}_mm`` and
``{a}_tcmd_A`` only, no ``line``, a clock of its own) is aligned with the
twin's run of the case's program as the diagnosis aligns it
(:func:`orchestrator.diagnose.prepare.prepare`); the replay then samples the
twin's commands at its own servo ticks (:meth:`~orchestrator.diagnose.prepare.Prepared.twin_commands`),
starts on the controller's tick grid (``Prepared.t_start``) and carries the
cutting forces (``Prepared.disturbance``: recorded, or the twin's predicted
ones for a case with a ``[stock]``). That alignment fits the twin's actual
positions, whose servo lag depends on the very scale factors being
identified (``1/(Kp Spp)``: 3.3 ms of clock error for Spp 1.2 against 1), so
a residual clock shift per case is fitted together with the scale factors:
the replay's outputs are compared ``shift`` earlier on its clock (logger
offset = alignment offset + shift; the tick phase stays the controller's). With commands, the residual ``e - e_sim`` is the same as
``x_sim - x`` on positions.

Residuals per sample and axis, with weights ``w1`` [1/µm] and ``w2`` [1/A]
(default: the reciprocal RMS of the measured channel, so both count alike)::

    default   r = [ w1 (e - e_sim) ; w2 (Atc - Atc_sim) ]      (stacked)
    paper-ga  eG = w1 (e - e_sim) + w2 (Atc - Atc_sim)        (Eq. 9, summed)

and the reported fitness is ``J = sum r^2 + max |r|`` (Eq. 7) of the
stacked residual for both methods. The paper's summed form lets the two
errors cancel each other; stacking them cannot, which is why the default
uses it.

``"default"``
    Trust-region least squares (scipy) on ``log S`` starting from ``Spp``
    estimated from the steady-state following error of the constant-velocity
    windows, with the Jacobian from one batched replay per iteration (members:
    the point and one perturbation per factor, all axes at once).
``"paper-ga"``
    pymoo GA, population 50, at most 100 generations, fitness limit 10
    (Section 2.3); one GA per axis in lockstep, one batched replay (B = 50)
    per generation. It runs on the samples left after the glitch screening
    of the least-squares fit (:func:`_screen_glitches`), as the default does.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np
from scipy.optimize import least_squares

from ..case import Case
from ..errors import CncTwinError
from ..machine import Machine, load_machine
from .closed_loop import replay
from .common import fitted_machine, provenance, write_outputs
from .data import CaseData, check_columns, load_inputs, measured_rows
from .errors import IdentificationError
from .ga import paper_objective, run_ga_lockstep
from .journal import Journal
from .segments import SegmentSettings, find_segments
from .start_state import LOG_POSITION_NOISE_M, AxisStart, estimate_start, start_window

_log = logging.getLogger(__name__)

FACTORS = ("position_scale", "velocity_p_scale", "velocity_i_scale")
SYMBOLS = ("Spp", "Svp", "Svi")
PAPER_GENERATIONS = 100
PAPER_FITNESS_LIMIT = 10.0
#: Search box of the scale factors.
BOUNDS = (0.2, 5.0)
#: Search box of the residual clock shift of a log aligned with the twin, ms.
SHIFT_BOUNDS_MS = (-20.0, 20.0)


@dataclass
class _Series:
    """One case (or its axes of one command source), prepared: times, references, measured error and current.

    ``ref[a]`` is the recorded reference [m] at ``t`` (``source == "recorded"``) or, for a log without
    commands (``source == "twin"``), ``f(q)``: the twin's command at replay-clock times ``q``; ``cmd`` then
    holds it at ``t`` and ``e = cmd - actual``.
    """

    data: CaseData
    t: np.ndarray
    ref: dict                         # axis -> m at t, or callable
    x0: dict[str, float]              # m
    e: dict[str, np.ndarray]          # µm
    cur: dict[str, np.ndarray]        # A
    source: str = "recorded"
    cmd: dict[str, np.ndarray] = field(default_factory=dict)   # m at t (twin commands)
    between: dict | None = None       # axis -> f(q) [m]: a coarse recorded reference at the servo ticks
    t_start: float | None = None     # first servo tick [s]: the controller's grid (None: the first sample)
    disturbance: dict | None = None
    offset: float = 0.0               # logger clock minus program clock, s
    offset_method: str = ""
    forces: str = "none"
    start: dict[str, AxisStart] = field(default_factory=dict)   # the state at the log's first sample


def _starts(d: CaseData, axes: Sequence[str], machine: Machine) -> dict[str, AxisStart]:
    """Axis -> the motion at the recording's first sample (:func:`.start_state.estimate_start`).

    A log that starts while an axis moves is replayed from that state, not from rest: started at rest on the
    first sample of a log cut into a 500 mm/min plateau, the replay's catching up gave Svp 0.94 and Svi 0.68
    for 0.8 and 1.0 (residual 3.5 µm, 0.20 A against 0.29 µm, 0.020 A for the whole log). The fit takes a
    production log's position noise at least (:data:`.start_state.LOG_POSITION_NOISE_M`): the twin's own run
    logged in 1 ms pairs every 5 ms gave Z Svp 0.86 and Svi 4.7 from a start velocity of 0.17 um/s.
    """
    rec = d.recording
    t = np.asarray(rec.t, dtype=float)
    return {a: estimate_start(t, np.asarray(rec[f"{a}_mm"], dtype=float) * 1e-3,
                              np.asarray(rec[f"{a}_tcmd_A"], dtype=float), start_window(machine, a),
                              min_noise=LOG_POSITION_NOISE_M)
            for a in axes}


@dataclass
class ServoFit:
    """Result of :func:`identify_servo` (attributes ending in ``_``).

    Attributes
    ----------
    scales_ : dict
        ``scales_[axis] = {"Spp": ..., "Svp": ..., "Svi": ...}``.
    fitness_ : dict
        Axis -> ``J = sum r^2 + max |r|`` of the stacked weighted residual.
    rms_ : dict
        Axis -> ``{"following_error_um": ..., "current_A": ...}`` residual RMS.
    weights_ : dict
        Axis -> ``(w1 [1/µm], w2 [1/A])``.
    iterations_ : int
        Optimiser iterations (generations for the GA).
    simulations_ : int
        Batched closed-loop replays run.
    machine_ : Machine
    provenance_ : dict
    method : str
    wall_time_ : float
    traces_ : list of dict
        Per case: ``t``, and per axis measured / simulated error and current (for plots).
    commands_ : dict
        Case -> where the replay's commands came from: ``"recorded"``, or for a log without them
        ``"twin, aligned: offset … s, method …"`` (the logger clock minus the program clock after the
        joint fit, and how the offset was found).
    excluded_ : list of str
        Logger glitches left out of the fit, ``"file:line axis channel"`` (see :func:`_screen_glitches`).
    notes_ : list of str
        Rows left out because a needed cell was empty (not measured), per case (``report.json`` -> ``notes``).
    """

    scales_: dict[str, dict[str, float]]
    fitness_: dict[str, float]
    rms_: dict[str, dict[str, float]]
    weights_: dict[str, tuple[float, float]]
    iterations_: int
    simulations_: int
    machine_: Machine
    provenance_: dict[str, str]
    method: str
    wall_time_: float
    cases: list[str] = field(default_factory=list)
    traces_: list[dict] = field(default_factory=list, repr=False)
    commands_: dict[str, str] = field(default_factory=dict)
    excluded_: list[str] = field(default_factory=list)
    notes_: list[str] = field(default_factory=list)

    def report(self) -> dict:
        """JSON-ready report (``commands``: per case where the commands came from)."""
        return {
            "kind": "servo", "method": self.method, "cases": self.cases, "wall_time_s": self.wall_time_,
            "commands": self.commands_, "excluded_samples": self.excluded_, "notes": self.notes_,
            "iterations": self.iterations_, "batched_simulations": self.simulations_,
            "axes": {a: {**self.scales_[a], "fitness_J": self.fitness_[a],
                         "residual_rms_following_error_um": self.rms_[a]["following_error_um"],
                         "residual_rms_current_A": self.rms_[a]["current_A"],
                         "w1_per_um": self.weights_[a][0], "w2_per_A": self.weights_[a][1]}
                     for a in self.scales_},
        }

    def write(self, out: str | Path, plots: bool = True) -> dict[str, Path]:
        """Write ``machine.toml``, ``report.json`` and ``servo_<axis>.png`` (Fig. 5 style)."""
        files = write_outputs(out, self.machine_, self.provenance_, self.report())
        if plots:
            from .plots import servo_png

            for a in self.scales_:
                files[f"servo_{a}"] = servo_png(self, a, Path(out) / f"servo_{a}.png")
        return files


def _has(recording, name: str) -> bool:
    """The column exists and is not entirely empty (an optional column a logger left blank)."""
    return name in recording and bool(np.isfinite(np.asarray(recording[name], dtype=float)).any())


def _prepare(data: Sequence[CaseData], axes: Sequence[str] | None,
             machine: Machine, notes: list[str] | None = None) -> tuple[list[_Series], list[str]]:
    """The series to replay; rows without a needed cell (not measured) are left out, noted in ``notes``."""
    series, used = [], []
    for d in data:
        rec = d.recording
        present = [a for a in "xyz" if all(f"{a}{s}" in rec for s in ("_ref_mm", "_mm", "_tcmd_A"))
                   and _has(rec, f"{a}_ref_mm")]
        logged = [a for a in "xyz" if a not in present and all(f"{a}{s}" in rec for s in ("_mm", "_tcmd_A"))]
        want = list(axes) if axes else present + [a for a in logged if a not in present]
        if not want:
            raise IdentificationError(
                f"{d.source}: servo identification needs '<axis>_mm' and '<axis>_tcmd_A' of at least one axis "
                f"(with '<axis>_ref_mm' when the log has the commands); the recording has {rec.channels}"
            )
        needed = [c for a in want for c in ((f"{a}_ref_mm",) if a in present else ()) + (f"{a}_mm", f"{a}_tcmd_A")
                  if c in rec]
        rec, note = measured_rows(rec, ["t_s", *needed], f"servo identification of axis {', '.join(want)}")
        if note is not None:
            _log.warning("%s", note)
            if notes is not None:
                notes.append(note)
            d.recording = rec
        moving, from_twin = [], []
        for a in want:
            if a in logged:
                check_columns(rec, ["t_s", f"{a}_mm", f"{a}_tcmd_A"],
                              f"servo identification of axis {a} (commands from the twin's run of the program)")
                from_twin.append(a)
                continue
            check_columns(rec, ["t_s", f"{a}_ref_mm", f"{a}_mm", f"{a}_tcmd_A"], f"servo identification of axis {a}")
            if np.ptp(rec[f"{a}_ref_mm"]) > 1e-3:
                moving.append(a)
            elif axes:
                raise IdentificationError(f"{d.source}: axis {a} does not move (reference range below 1 µm)")
        if moving:
            t = np.asarray(rec.t, dtype=float)
            aligned = _Aligned(d, machine, moving)
            load, forces = _cutting_load(d, machine, moving, aligned)
            series.append(_Series(
                d, t,
                {a: np.asarray(rec[f"{a}_ref_mm"]) * 1e-3 for a in moving},
                {a: float(rec[f"{a}_mm"][0]) * 1e-3 for a in moving},
                {a: np.asarray(rec.following_error_um(a), dtype=float) for a in moving},
                {a: np.asarray(rec[f"{a}_tcmd_A"], dtype=float) for a in moving},
                disturbance=load, forces=forces, between=_between_samples(d, machine, moving, aligned),
                start=_starts(d, moving, machine), t_start=_controller_tick(d, machine, aligned),
            ))
        twin = _twin_series(d, from_twin, machine, explicit=bool(axes)) if from_twin else None
        if twin is not None:
            series.append(twin)
        used += [a for a in moving + (list(twin.ref) if twin is not None else []) if a not in used]
    if not series:
        raise IdentificationError(
            f"{', '.join(d.source for d in data)}: no axis moves; expected reciprocating runs "
            "(`cnctwin experiment servo`)"
        )
    return series, used


class _Aligned:
    """The diagnosis's alignment of a log with recorded commands with the twin's run, computed once when asked.

    Calling it gives the :class:`orchestrator.diagnose.prepare.Prepared` alignment, or raises the project error
    it raised (:class:`~orchestrator.diagnose.errors.DiagnosisError`, ...; every call, the same one).
    """

    def __init__(self, d: CaseData, machine: Machine, axes: list[str]) -> None:
        self.d, self.machine, self.axes = d, machine, list(axes)
        self._result: object = None

    def __call__(self):
        from ..diagnose.prepare import prepare as align_with_twin

        if self._result is None:
            try:
                self._result = align_with_twin(self.d.case, self.d.recording, self.machine, axes=self.axes)
            except CncTwinError as exc:
                self._result = exc
        if isinstance(self._result, Exception):
            raise self._result
        return self._result


#: Samples within this fraction of a position-loop period of the controller's ticks are on its tick grid (when
#: the alignment took the ticks from the recorded commands; from the current ripple it resolves 1/8 period).
ON_GRID_FRACTION = 0.02


def _controller_tick(d: CaseData, machine: Machine, aligned: _Aligned) -> float | None:
    """The controller's last position-loop tick at or before a log's first sample [s, logger clock], or None.

    The replay's position loop ticks every ``Tp`` from its first tick; started on the log's first sample, it
    samples the command and the feedback in the logger's phase, not the controller's. A logger whose samples
    fall between the controller's ticks (a clock of its own, a 0.25 ms phase) then gave Svi +15 % and Svp
    -4 % at twice the noise residual. The tick grid is the diagnosis's alignment with the twin's run
    (``Prepared.t_start``: to well below a microsecond on the twin's own logs). None (start on the first
    sample, as before) for a log on that grid (to :data:`ON_GRID_FRACTION` of a period, or to the 1/8 period
    the current ripple resolves when the commands differ from the twin's), or one that cannot be aligned.
    """
    from ..diagnose.prepare import PHASE_STEPS  # local: the diagnosis imports the identification's replay

    try:
        prep = aligned()
    except CncTwinError as exc:  # any project error of the alignment: replay as before, on the first sample
        _log.info("%s: replay ticks start on the first sample (not aligned with the twin: %s)", d.source, exc)
        return None
    tp = float(machine.si("servo")["position_loop_period"])
    t = np.asarray(d.recording.t, dtype=float)
    ticks = (t - prep.t_start) / tp
    tolerance = ON_GRID_FRACTION if prep.phase_from_commands else 1.0 / PHASE_STEPS
    if np.max(np.abs(ticks - np.round(ticks))) <= tolerance:
        return None
    return float(prep.t_start - tp * np.ceil((prep.t_start - t[0]) / tp - 1e-9))


def _cutting_load(d: CaseData, machine: Machine, axes: list[str],
                  aligned: _Aligned | None = None) -> tuple[dict | None, str]:
    """The cutting force the drives of a log with recorded commands carried: ``({axis: f(t)}, source)``.

    A log taken while cutting holds the cutting load in its currents (a 2 mm slot in A6061: about 1 A on the
    feeding axis and as much on the one at rest); a replay in the air would fit the scale factors to it.
    The forces are the recorded ``fx_N``/``fy_N`` when the log has them, else the twin's predicted ones
    when the case has a ``[stock]`` the program cuts (placed on the logger clock by the diagnosis's
    alignment, which uses the recorded commands here), else none (an air run, as the servo experiment).
    Recorded forces too coarse for the tooth load (fewer than 6 samples per tooth, e.g. 1 ms with 2 flutes at
    6000 rpm) are, with a ``[stock]``, the twin's load corrected by them (``prepare.corrected_forces``): the
    twin's own run of the paper part, with its 1 ms forces interpolated, gave Svi 0.21 on X and Svp 1.84 on Y.
    ``f(t)`` takes logger-clock times [s] and gives the force on the workpiece [N].
    """
    from ..diagnose.errors import DiagnosisError  # local: only cutting logs need the diagnosis's alignment
    from ..diagnose.prepare import predicted_forces, recorded_forces

    recorded = recorded_forces(d.recording)
    if d.case.stock is None:
        return recorded, "none" if recorded is None else "recorded"
    aligned = aligned or _Aligned(d, machine, axes)
    try:  # with a stock: recorded forces too coarse for the tooth load are corrected on the twin's (see prepare)
        prep = aligned()
    except DiagnosisError as exc:
        if recorded is not None:
            return recorded, "recorded"
        if predicted_forces(d.case, machine, lambda: 0.0) is None:
            return None, "none"          # the program never cuts the stock: an air run, nothing to place
        raise IdentificationError(
            f"{d.source}: the case has a [stock], so the drives carried the cutting load of {d.case.program}; "
            f"the log cannot be aligned with the twin's run to place the predicted forces: {exc}; record "
            "fx_N and fy_N, or remove [stock] from the case for an air run"
        ) from None
    return prep.disturbance, prep.forces_source


def _between_samples(d: CaseData, machine: Machine, axes: list[str],
                     aligned: _Aligned | None = None) -> dict | None:
    """Recorded commands sampled more coarsely than the interpolation, at any time: ``{axis: f(q)}`` [m], or None.

    Interpolated between the logger's samples, such a command loses the shape of every acceleration: the twin's
    own air run logged every 10 ms gave Svp 0.48 instead of 1, every 4 ms Svi 0.91 on Z. Here the twin's own
    command carries the recorded one between the samples, corrected by the recorded-minus-twin difference
    (exact at every sample), placed on the logger clock by the diagnosis's alignment
    (:meth:`orchestrator.diagnose.prepare.Prepared.twin_commands`). None for a log at the interpolation period
    (nothing to carry), or when the log cannot be aligned with the twin's run (the samples are interpolated).
    """
    from ..diagnose.errors import DiagnosisError  # local: only coarse logs need the diagnosis's alignment

    t = np.asarray(d.recording.t, dtype=float)
    period = float(machine.si("nck")["interpolation_period"])
    gaps = [float(np.max(np.diff(t[np.isfinite(np.asarray(d.recording[f"{a}_ref_mm"], dtype=float))])))
            for a in axes if np.isfinite(np.asarray(d.recording[f"{a}_ref_mm"], dtype=float)).sum() > 1]
    if not gaps or max(gaps) <= 1.5 * period:
        return None
    try:
        prep = (aligned or _Aligned(d, machine, axes))()
    except DiagnosisError as exc:
        _log.info("%s: recorded commands interpolated between samples (not aligned with the twin: %s)", d.source, exc)
        return None
    twin = prep.twin_commands()
    return {a: (lambda q, f=twin[a]: f(q, 0.0)) for a in axes if a in twin} or None


def _twin_series(d: CaseData, axes: list[str], machine: Machine, explicit: bool) -> _Series | None:
    """A log without commands: aligned with the twin's run of the program (the diagnosis's alignment)."""
    from ..diagnose.errors import DiagnosisError  # local: only logs without commands need the diagnosis
    from ..diagnose.prepare import prepare as align_with_twin

    try:
        prep = align_with_twin(d.case, d.recording, machine, axes=list(axes))
    except DiagnosisError as exc:
        msg = str(exc)
        msg = msg[len(d.source) + 2:] if msg.startswith(f"{d.source}: ") else msg
        raise IdentificationError(
            f"{d.source}: the recording has no commanded positions ('<axis>_ref_mm' missing for axis "
            f"{', '.join(axes)}) and cannot be aligned with the twin's run of {d.case.program} to take its commands "
            f"instead: {msg}; record the commands, or check that the log belongs to that program"
        ) from None
    moving = [a for a in axes if a in prep.axes]
    if explicit and len(moving) < len(axes):
        still = [a for a in axes if a not in moving]
        raise IdentificationError(f"{d.source}: axis {', '.join(still)} does not move in the twin's run of "
                                  f"{d.case.program} (commanded stroke below 10 µm)")
    if not moving:
        return None
    # a member shifted by ``lag`` compares the log at ``t`` with its replay at ``t - lag``, which starts at
    # ``t_start``: samples before the latest such start (one position-loop period later) would meet a held state
    tp = float(machine.si("servo")["position_loop_period"])
    sel = prep.valid & (np.asarray(prep.t, dtype=float) >= prep.t_start + tp + max(map(abs, SHIFT_BOUNDS_MS)) * 1e-3)
    for a in moving:
        sel &= np.isfinite(prep.fe[a]) & np.isfinite(prep.current[a])
    _check_same_program(d, prep, moving, sel)
    if sel.sum() < 3:
        raise IdentificationError(f"{d.source}: fewer than 3 samples overlap the twin's run of {d.case.program} "
                                  f"after alignment (offset {prep.offset:.6g} s, {prep.offset_method})")
    twin = prep.twin_commands()
    ref = {a: (lambda q, f=twin[a]: f(q, 0.0)) for a in moving}
    return _Series(
        d, prep.t[sel], ref,
        {a: float(ref[a](np.array([prep.t_start]))[0]) for a in moving},
        {a: prep.fe[a][sel] for a in moving},
        {a: np.asarray(prep.current[a], dtype=float)[sel] for a in moving},
        source="twin", cmd={a: prep.commands[a][sel] for a in moving}, t_start=prep.t_start,
        disturbance=prep.disturbance, offset=prep.offset, offset_method=prep.offset_method,
        forces=prep.forces_source, start=_starts(d, moving, machine),
    )


#: A log whose positions differ from the twin's run of the case's program by more than this fraction of the
#: stroke (rms, after alignment) is not a log of that program: scale factors anywhere in :data:`BOUNDS` move
#: the path by the lag ``v / (Pp Spp)`` only, a few per cent of a servo experiment's stroke.
OTHER_PROGRAM_FRACTION = 0.1


def _check_same_program(d: CaseData, prep, axes: list[str], sel: np.ndarray) -> None:
    """Refuse a log without commands that does not follow the twin's run of the case's program.

    Raises
    ------
    IdentificationError
        Naming the recording, its first line off the twin's path, and the program (a Servo Guide log of
        another program was fitted silently: Svi at the bound 0.2, residual 1.4 mm).
    """
    t = np.asarray(prep.t, dtype=float)
    t_nc = np.asarray(prep.nc.t, dtype=float)
    for a in axes:
        twin = np.interp(t - prep.offset, t_nc, np.asarray(prep.nc[f"{a}_mm"], dtype=float)) * 1e-3
        actual = np.asarray(prep.commands[a], dtype=float) - np.asarray(prep.fe[a], dtype=float) * 1e-6
        diff = (actual - twin)[sel]
        stroke = float(np.ptp(twin[sel])) if sel.any() else 0.0
        if diff.size == 0 or stroke <= 0.0:
            continue
        rms = float(np.sqrt(np.mean(diff ** 2)))
        if rms > OTHER_PROGRAM_FRACTION * stroke:
            first = int(np.flatnonzero(sel)[np.argmax(np.abs(diff) > OTHER_PROGRAM_FRACTION * stroke)])
            raise IdentificationError(
                f"{d.recording.where(first)}: axis {a} does "
                f"not follow the twin's run of {d.case.program}: {rms * 1e3:.3g} mm rms off its path after "
                f"alignment (offset {prep.offset:.6g} s), {100.0 * rms / stroke:.0f} % of its {stroke * 1e3:.3g} mm "
                "stroke; is this the recording of another program?"
            )


def _sample(start: float, step: float, values: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Linear interpolation of ``values`` (m, B) on the grid ``start + step k`` [s] at ``q`` (n, B), held outside.

    The grid's step is given, not taken from two grid times: on a logger clock of 1.7e9 s (Unix time) those
    are 2.4e-7 s apart from ``step`` (0.1 % of a 0.25 ms tick), and 40 000 ticks on the samples were 40 ticks
    off (Spp 1.02, Svp 1.49 for 0.9, 1.2).
    """
    x = (q - start) / step
    k = np.clip(np.floor(x).astype(int), 0, values.shape[0] - 2)
    f = np.clip(x - k, 0.0, 1.0)
    return np.take_along_axis(values, k, 0) * (1.0 - f) + np.take_along_axis(values, k + 1, 0) * f


def _simulate(machine: Machine, series: _Series, scales: dict[str, np.ndarray],
              shift: np.ndarray | None = None, smooth: bool = False) -> tuple[dict, dict]:
    """Replay one case with per-member scale factors ``scales[axis]`` of shape (B, 3).

    ``shift`` (B,) [s]: for a log aligned with the twin, each member's outputs are sampled ``shift`` earlier
    on the replay clock (a residual clock offset: logger offset = ``offset + shift``; the servo ticks stay on
    the controller's grid). ``smooth``: the simulated current is averaged over a position-loop period first
    (its jump at every position-loop tick makes the fit's cost a staircase in ``shift``).
    """
    batch = next(iter(scales.values())).shape[0]
    mcu = {f"{a}_{name}": scales[a][:, j] for a in series.ref for j, name in enumerate(FACTORS) if a in scales}
    if series.source == "recorded":
        refs = {a: (series.between or {}).get(a, r) for a, r in series.ref.items()}
        run = replay(machine, series.t, refs, batch=batch, mcu_values=mcu, initial_position=series.x0,
                     t_start=series.t_start, disturbance=series.disturbance, start=series.start)
        e = {a: (series.ref[a][:, None] - run.position[a]) * 1e6 for a in series.ref}
        return e, run.current
    tv = float(machine.si("servo")["velocity_loop_period"])
    span = float(series.t[-1]) - series.t_start + max(map(abs, SHIFT_BOUNDS_MS)) * 1e-3
    grid = series.t_start + tv * np.arange(int(np.ceil(span / tv)) + 2)
    lag = np.zeros(batch) if shift is None else np.broadcast_to(np.asarray(shift, dtype=float), (batch,))
    # the replay at q is compared with the log at q + shift: it starts from the log's state there
    run = replay(machine, series.t, series.ref, batch=batch, mcu_values=mcu, initial_position=series.x0,
                 t_out=grid, t_start=series.t_start, disturbance=series.disturbance, start=series.start,
                 start_at=series.t_start + lag)
    q = series.t[:, None] - lag[None, :]
    e = {a: (series.cmd[a][:, None] - _sample(series.t_start, tv, run.position[a], q)) * 1e6 for a in series.ref}
    cur = run.current
    if smooth:
        width = max(int(round(float(machine.si("servo")["position_loop_period"]) / tv)), 1)
        kernel = np.ones(width) / width
        cur = {a: np.apply_along_axis(np.convolve, 0, c, kernel, "same") for a, c in cur.items()}
    return e, {a: _sample(series.t_start, tv, cur[a], q) for a in series.ref}


def _initial_spp(machine: Machine, series: list[_Series], axis: str) -> float:
    """``Spp`` from steady following error ``e = v / (Pp Spp)`` on constant-velocity windows."""
    pp = float(machine.si(f"axis.{axis}")["position_gain"])
    gains = []
    for s in series:
        if axis not in s.ref:
            continue
        rec = s.data.recording
        for seg in find_segments(rec, axis, 1.0, SegmentSettings(settle_s=0.1)):
            sel = (s.t >= seg.t_start) & (s.t <= seg.t_end)
            e = float(np.mean(s.e[axis][sel])) * 1e-6
            if abs(seg.velocity) > 1e-5 and e * seg.velocity > 0:
                gains.append(seg.velocity / e / pp)
    return float(np.clip(np.median(gains), *BOUNDS)) if gains else 1.0


def identify_servo(
    cases: Iterable[str | Path | Case],
    method: str = "default",
    seed: int = 0,
    axes: Sequence[str] | None = None,
    machine: str | Path | Machine | None = None,
    weights: tuple[float, float] | None = None,
    max_iterations: int = 30,
    journal: Journal | None = None,
) -> ServoFit:
    """Identify the servo scale factors Spp, Svp, Svi per axis.

    Parameters
    ----------
    cases : iterable of case folders / ``case.toml`` / Case
        Reciprocating runs (``cnctwin experiment servo``) with ``t_s``,
        ``{a}_ref_mm``, ``{a}_mm``, ``{a}_tcmd_A``. Without ``{a}_ref_mm``
        (a servo log), the commands are the twin's run of the case's program,
        aligned with the log (see the module docstring and ``ServoFit.commands_``).
    method : {"default", "paper-ga"}
    seed : int
        GA seed.
    axes : sequence of str, optional
        Axes to identify (default: every recorded axis that moves).
    machine : name, path or Machine, optional
        Parameters used in the replay (friction, masses, nominal gains) and
        written back with the fitted factors; default the first case's.
    weights : (w1, w2), optional
        ``w1`` [1/µm], ``w2`` [1/A] of Eq. (9); default the reciprocal RMS
        of the measured following error and current of each axis.
    max_iterations : int
        Iteration cap of the default optimiser.
    journal : Journal, optional
        Records the result of every batched replay (residuals and Jacobian of a
        least-squares evaluation, fitness of a GA generation) for checkpoints
        and resume (see :func:`orchestrator.identify.identify`).

    Returns
    -------
    ServoFit
    """
    start = time.perf_counter()
    data = load_inputs(cases)
    base = machine if isinstance(machine, Machine) else (
        load_machine(machine) if machine is not None else data[0].case.machine)
    notes: list[str] = []
    series, used = _prepare(data, axes, base, notes)
    w: dict[str, tuple[float, float]] = {}
    masks: dict[tuple[int, str], np.ndarray] = {}   # (series, axis) -> 0/1 per stacked residual (glitches left out)

    def set_weights() -> None:
        """``w[a]``: the given weights, else 1/RMS of each measured channel over the samples not left out."""
        for a in used:
            keep = [(s, masks.get((i, a), np.ones(2 * s.t.size)) > 0.0) for i, s in enumerate(series) if a in s.e]
            e_all = np.concatenate([s.e[a][k[: s.t.size]] for s, k in keep])
            c_all = np.concatenate([s.cur[a][k[s.t.size:]] for s, k in keep])
            w[a] = weights or (1.0 / max(float(np.sqrt(np.mean(e_all ** 2))), 1e-3),
                               1.0 / max(float(np.sqrt(np.mean(c_all ** 2))), 1e-3))

    set_weights()
    counter = {"sims": 0}
    journal = journal or Journal()

    def residuals(scales: dict[str, np.ndarray], summed: bool = False,
                  shifts: dict[int, np.ndarray] | None = None, smooth: bool = False) -> dict[str, np.ndarray]:
        """Weighted residuals per axis, shape (B, m_a); ``shifts[i]`` (B,) [s] for the series aligned with the twin."""
        parts: dict[str, list[np.ndarray]] = {a: [] for a in used}
        for i, s in enumerate(series):
            sub = {a: scales[a] for a in s.ref}
            e_sim, c_sim = (_simulate(base, s, sub, shifts.get(i), smooth) if shifts
                            else _simulate(base, s, sub))
            for a in s.ref:
                de = w[a][0] * (s.e[a][:, None] - e_sim[a]).T
                dc = w[a][1] * (s.cur[a][:, None] - c_sim[a]).T
                if (i, a) in masks:
                    de, dc = de * masks[i, a][: s.t.size], dc * masks[i, a][s.t.size:]
                parts[a].append(de + dc if summed else np.concatenate([de, dc], axis=1))
        return {a: np.concatenate(p, axis=1) for a, p in parts.items()}

    def journaled(stage: str, key: object, compute):
        """One batched replay of every case, read back from the journal when a resumed job already did it."""
        counter["sims"] += len(series)
        return journal.memo(stage, key, compute)

    if method not in ("default", "paper-ga"):
        raise IdentificationError(f"unknown servo method {method!r}; expected 'default' or 'paper-ga'")
    # every method starts with the least-squares fit: its residuals screen the logger's glitches (paper-ga too:
    # its GA then runs on the screened samples, a glitch would dominate its J = sum e^2 + max|e| as well), and
    # paper-ga on a log without commands takes the clock shifts from it
    scales, shifts, iterations = _fit_least_squares(base, series, used, residuals, max_iterations, journaled)
    at = residuals({a: scales[a][None, :] for a in used},
                   shifts={i: np.full(1, v) for i, v in shifts.items()} if shifts else None)
    glitches = _screen_glitches(series, used, at, masks)
    if glitches:
        set_weights()  # the weights 1/RMS of the measurement are not set by the glitches either
    if method == "default" or any(s.source == "twin" for s in series):
        if glitches:
            # a logger's bad sample (a position jump, a current spike) dominates the squared residual: fit again
            # without it, from there (the first fit on one 0.5 mm position glitch gave Svp 1.08 for 1.2)
            tag = ".screened." + ",".join(glitches)
            scales, shifts, more = _least_squares_stage(base, series, used, residuals, max_iterations, journaled,
                                                        start=(scales, shifts), tag=tag)
            iterations += more
    if method == "paper-ga":
        scales, iterations = _fit_ga(used, residuals, seed, journaled, shifts)

    def member_shifts(b: int) -> dict[int, np.ndarray]:
        return {i: np.full(b, v) for i, v in shifts.items()}

    counter["sims"] += len(series)
    final = residuals({a: scales[a][None, :] for a in used}, shifts=member_shifts(1))
    fitness, rms = {}, {}
    for a in used:
        r = final[a][0]
        keep = np.concatenate([masks.get((i, a), np.ones(2 * s.t.size)) for i, s in enumerate(series)
                               if a in s.ref]) > 0.0
        is_e = np.concatenate([np.repeat([True, False], s.t.size) for s in series if a in s.ref])
        fitness[a] = float(paper_objective(r[keep]))
        rms[a] = {"following_error_um": float(np.sqrt(np.mean(r[keep & is_e] ** 2)) / w[a][0]),
                  "current_A": float(np.sqrt(np.mean(r[keep & ~is_e] ** 2)) / w[a][1])}
    traces = []
    for i, s in enumerate(series):
        counter["sims"] += 1
        e_sim, c_sim = _simulate(base, s, {a: scales[a][None, :] for a in s.ref}, member_shifts(1).get(i))
        ref_mm = {a: (s.ref[a] if s.source == "recorded" else s.cmd[a]) * 1e3 for a in s.ref}
        traces.append({"case": s.data.name, "t": s.t, "ref_mm": ref_mm,
                       "e_meas": s.e, "e_sim": {a: e_sim[a][:, 0] for a in s.ref},
                       "cur_meas": s.cur, "cur_sim": {a: c_sim[a][:, 0] for a in s.ref}})
    names = [d.name for d in data]
    commands = _command_sources(data, series, shifts)
    what = "recorded references" if all(s.source == "recorded" for s in series) else \
        "recorded references or the twin's commands aligned with the log"
    source = provenance(f"servo {method} (closed-loop replay of {what}, Eq. 7-9)", names)
    updates = {f"axis.{a}": {f: float(scales[a][j]) for j, f in enumerate(FACTORS)} for a in used}
    fitted, extra = fitted_machine(base, updates, source, "servo")
    return ServoFit(
        {a: dict(zip(SYMBOLS, map(float, scales[a]))) for a in used}, fitness, rms, w, iterations,
        counter["sims"], fitted, extra, method, time.perf_counter() - start, names, traces, commands, glitches,
        notes,
    )


#: A residual farther than this many robust standard deviations (1.4826 MAD of its axis and channel) ...
GLITCH_SIGMAS = 12.0
#: ... in a run of at most this many samples is a logger glitch (a model error lasts longer) ...
GLITCH_RUN = 3
#: ... and at most this fraction of the samples may be left out so (more is not a glitch: the fit stands).
GLITCH_FRACTION = 0.005


def _screen_glitches(series: list[_Series], used: list[str], residual: dict[str, np.ndarray],
                     masks: dict[tuple[int, str], np.ndarray]) -> list[str]:
    """Find isolated bad samples in the weighted residuals at a fit; set ``masks`` to leave them out.

    Returns ``"file:line axis channel"`` per sample left out (empty when none, or when more than
    :data:`GLITCH_FRACTION` of an axis's samples would be: then the residual RMS tells).
    """
    found: list[str] = []
    for a in used:
        r = residual[a][0]
        owners = [(i, s) for i, s in enumerate(series) if a in s.ref]
        sizes = [2 * s.t.size for _, s in owners]
        bad = np.zeros(r.size, dtype=bool)
        gross = np.zeros(r.size, dtype=bool)
        start = 0
        pieces = []
        for (i, s), n in zip(owners, sizes):
            pieces.append((i, s, start, n))
            start += n
        for channel in (0, 1):
            idx = np.concatenate([np.arange(st + channel * s.t.size, st + (channel + 1) * s.t.size)
                                  for _, s, st, _ in pieces])
            x = r[idx]
            dev = np.abs(x - np.median(x))
            # the MAD alone is too narrow where an axis rests most of the time (its quantised residual is
            # mostly exactly 0): at least the standard deviation of all but the largest 0.5 %
            inner = dev[dev <= np.percentile(dev, 99.5)]
            scale = max(1.4826 * float(np.median(dev)), float(np.sqrt(np.mean(inner ** 2))))
            if scale <= 0.0:
                continue
            far = dev > GLITCH_SIGMAS * scale
            # a gross glitch biases the first fit, and the misfit it leaves is itself many MADs wide: one
            # 10 times the 99.5th percentile of the residuals is a glitch whatever the rest looks like
            top = 10.0 * float(np.percentile(dev, 99.5))
            for lo, hi in _true_runs(far):
                if hi - lo <= GLITCH_RUN:
                    bad[idx[lo:hi]] = True
            for lo, hi in _true_runs(dev > max(top, GLITCH_SIGMAS * scale)):
                if hi - lo <= GLITCH_RUN:
                    gross[idx[lo:hi]] = True
        if bad.sum() > GLITCH_FRACTION * r.size:
            bad = gross
        bad |= gross
        if not bad.any() or bad.sum() > GLITCH_FRACTION * r.size:
            continue
        for i, s, st, n in pieces:
            mine = bad[st:st + n]
            if not mine.any():
                continue
            masks[i, a] = (~mine).astype(float)
            rec = s.data.recording
            for k in np.flatnonzero(mine):
                row = int(np.searchsorted(np.asarray(rec.t, dtype=float), s.t[k % s.t.size]))
                what = "following error" if k < s.t.size else "current"
                found.append(f"{rec.where(row)} {a} {what}")
    return found


def _true_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Half-open index ranges of the True runs of ``mask``."""
    m = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(m == 1), np.flatnonzero(m == -1)))


def _command_sources(data: Sequence[CaseData], series: list[_Series], shifts: dict[int, float]) -> dict[str, str]:
    """Case -> where its replay's commands came from (``"recorded"`` or the twin's, with the alignment)."""
    out = {}
    for d in data:
        parts = []
        mine = [(i, s) for i, s in enumerate(series) if s.data is d]
        for i, s in mine:
            if s.source == "recorded":
                text = "recorded" if s.forces == "none" else f"recorded; cutting forces on the drives: {s.forces}"
            else:
                shift = shifts.get(i, 0.0)
                text = (f"twin, aligned: offset {s.offset + shift:.6f} s, method {s.offset_method}; "
                        f"residual clock shift {shift * 1e3:+.3f} ms fitted with the scale factors; "
                        f"cutting forces on the drives: {s.forces}")
            parts.append(text if len(mine) == 1 else f"{', '.join(s.ref)}: {text}")
        out[d.name] = " | ".join(parts) if parts else "not used (no axis moves)"
    return out


def _fit_least_squares(base, series, used, residuals, max_iterations,
                       journaled) -> tuple[dict[str, np.ndarray], dict[int, float], int]:
    """Scale factors per axis (and a clock shift [s] per series aligned with the twin) by trust-region LS.

    With logs aligned with the twin, a first fit compares the current averaged over a position-loop
    period (smooth in the shift: the clock shift and ``Spp`` trade off along a long valley of the
    following error, which the current's per-tick jumps would cut into local minima), a second one
    the current as logged, from there.
    """
    twin = [i for i, s in enumerate(series) if s.source == "twin"]
    if not twin:
        return _least_squares_stage(base, series, used, residuals, max_iterations, journaled)
    scales, shifts, n1 = _least_squares_stage(base, series, used, residuals, max_iterations, journaled, smooth=True)
    scales, shifts, n2 = _least_squares_stage(base, series, used, residuals, max_iterations, journaled,
                                              start=(scales, shifts))
    return scales, shifts, n1 + n2


def _least_squares_stage(base, series, used, residuals, max_iterations, journaled, smooth: bool = False,
                         start: tuple | None = None,
                         tag: str = "") -> tuple[dict[str, np.ndarray], dict[int, float], int]:
    """One trust-region fit; ``start`` = (scales, shifts [s]) of a previous stage, else the default start.

    ``tag`` names the stage in the journal (the samples left out after screening for glitches)."""
    twin = [i for i, s in enumerate(series) if s.source == "twin"]
    if start is None:
        z0 = np.concatenate([[np.log(_initial_spp(base, series, a)), 0.0, 0.0] for a in used])
    else:
        z0 = np.concatenate([np.log(start[0][a]) for a in used])
    n_scale = z0.size
    step = 1e-3
    members = 4 + (1 if twin else 0)
    # row -> series of the stacked residual of each axis (error then current per series, as `residuals` stacks)
    owner = {a: np.concatenate([np.full(2 * s.t.size, i) for i, s in enumerate(series) if a in s.ref]) for a in used}
    cache: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

    def evaluate(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        key = np.round(z, 12).tobytes()
        if key not in cache:
            cache.clear()
            stage = "servo.least_squares" + (".smooth" if smooth else "") + tag
            cache[key] = journaled(stage, np.round(z, 12), lambda: residuals_and_jacobian(z))
        return cache[key]

    def residuals_and_jacobian(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Residual vector at ``z`` and its forward-difference Jacobian: one batched replay of 4 (5) members.

        Members: the point, one perturbation per factor (every axis at once: the axes are independent),
        and with logs aligned with the twin one perturbation of every series' clock shift [ms].
        """
        scales = {}
        for i, a in enumerate(used):
            zz = np.tile(z[3 * i:3 * i + 3], (members, 1))
            zz[1:4] += step * np.eye(3)
            scales[a] = np.exp(zz)
        shifts = {}
        for k, i in enumerate(twin):
            ms = np.full(members, z[n_scale + k])
            ms[4] += step
            shifts[i] = ms * 1e-3
        r = residuals(scales, shifts=shifts, smooth=smooth) if twin else residuals(scales)
        vec = np.concatenate([r[a][0] for a in used])
        jac = np.zeros((vec.size, z.size))
        row = 0
        for i, a in enumerate(used):
            m = r[a].shape[1]
            jac[row:row + m, 3 * i:3 * i + 3] = ((r[a][1:4] - r[a][0]) / step).T
            for k, j in enumerate(twin):
                mine = owner[a] == j
                jac[row:row + m, n_scale + k][mine] = ((r[a][4] - r[a][0]) / step)[mine]
            row += m
        return vec, jac

    lo, hi = np.log(BOUNDS[0]), np.log(BOUNDS[1])
    z0 = np.clip(z0, lo + 1e-6, hi - 1e-6)
    bounds = (lo, hi)
    if twin:
        z0 = np.concatenate([z0, [1e3 * start[1][i] if start else 0.0 for i in twin]])
        bounds = (np.concatenate([np.full(n_scale, lo), np.full(len(twin), SHIFT_BOUNDS_MS[0])]),
                  np.concatenate([np.full(n_scale, hi), np.full(len(twin), SHIFT_BOUNDS_MS[1])]))
    sol = least_squares(lambda z: evaluate(z)[0], z0, jac=lambda z: evaluate(z)[1], bounds=bounds,
                        method="trf", x_scale=1.0, xtol=1e-8, ftol=1e-10, gtol=1e-10, max_nfev=max_iterations)
    return ({a: np.exp(sol.x[3 * i:3 * i + 3]) for i, a in enumerate(used)},
            {i: float(sol.x[n_scale + k]) * 1e-3 for k, i in enumerate(twin)}, int(sol.nfev))


def _fit_ga(used, residuals, seed, journaled,
            shifts: dict[int, float] | None = None) -> tuple[dict[str, np.ndarray], int]:
    """The paper's GA per axis in lockstep; ``shifts`` [s]: clock shifts of logs aligned with the twin (fixed)."""
    bounds = [(np.full(3, BOUNDS[0]), np.full(3, BOUNDS[1])) for _ in used]
    def evaluate(xs: list[np.ndarray]) -> list[np.ndarray]:
        # an axis whose GA has stopped gets filler members (factors 1), evaluated and ignored
        p = max(x.shape[0] for x in xs)
        scales = {a: (np.vstack([x, np.ones((p - x.shape[0], 3))]) if x.shape[0] < p else x)
                  for a, x in zip(used, xs)}
        r = (residuals(scales, summed=True, shifts={i: np.full(p, v) for i, v in shifts.items()}) if shifts
             else residuals(scales, summed=True))
        return [paper_objective(r[a])[: x.shape[0]] for a, x in zip(used, xs)]

    def evaluate_generation(xs: list[np.ndarray]) -> list[np.ndarray]:
        """The fitness of one generation of every axis's GA (journaled: the small fitness arrays only)."""
        return journaled("servo.ga_generation", list(xs), lambda: evaluate(xs))

    results = run_ga_lockstep(evaluate_generation, bounds, PAPER_GENERATIONS, PAPER_FITNESS_LIMIT, seed=seed)
    return {a: res.x for a, res in zip(used, results)}, max(res.generations for res in results)
