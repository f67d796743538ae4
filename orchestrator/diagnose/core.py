"""``diagnose``: locate the mismatch between a recording and the twin, name the missing physics, refit it.

Pipeline (each step its own module):

1. :mod:`.prepare` / :mod:`.align` — the twin's NC run of the program, the
   logger time offset (block transitions, then the servo-clock phase from the
   current ripple), commanded positions (recorded, else the twin's), measured
   following error and current;
2. :mod:`.columns` — baseline replay of the servo loop and drives on the
   commands, noise floors, and the library of effect columns (one batched
   replay + kinematics);
3. :mod:`.select` — sparse regression with BIC and minimum gains, per axis;
4. :mod:`.refit` — the chosen effects and the identified scale factors
   refitted together by batched closed-loop replay;
5. :mod:`.locate` — where each effect and any unexplained residual sit
   (time windows, lines, events, frequencies); RMS before / after, also on a
   held-out case.

With forces in the recording and a stock in the case, the cutting process is
diagnosed as well (:mod:`.cutting_core`: forces and spindle speed, effects
without ``axis``), and the recorded forces load the replayed drives.
"""
from __future__ import annotations

import datetime as _dt
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..case import Case, load_case, missing_file
from ..machine import Machine, load_machine
from ..recording import SPEC_COLUMNS, Recording, RecordingError
from ..recording_csv import near_miss_hint
from .columns import AxisColumns, build
from .cutting import FORCE_CHANNELS, has_forces
from .cutting_core import CuttingResult, diagnose_cutting
from .cutting_library import component_values
from .cutting_load import model_loads
from .cutting_merge import holdout_cutting, merge_cutting
from .errors import DiagnosisError
from .force_only import ForceOnly, force_only_recording, measures_positions, needs_force_clock, refine_with_effects
from .library import CHANNEL_SCALE, machine_keys
from .locate import Locator, residual_windows
from .model import Model, Simulated, simulate
from .prepare import Prepared, prepare, recorded_forces
from .refit import Parameter, RefitResult, artefact_values, projectors, refit, residuals
from .rest import leave_out_held_current
from .select import MIN_GAIN, Choice, Selection, select

#: Residual RMS (noise floors) above which a channel's remaining residual is looked at for `unexplained`.
UNEXPLAINED_SIGMA = 3.0
#: Model entries that are not effects (identified parameters, timing).
PSEUDO_EFFECTS = ("servo_scales", "command_shift")
#: NC-kernel difference (recorded minus twin command) reported as unexplained above this RMS, mm.
NC_DIFFERENCE_MM = 0.005


@dataclass
class CaseResult:
    """One case replayed with the baseline and with the diagnosed model."""

    name: str
    prep: Prepared
    cols: dict[str, AxisColumns]
    sim: Simulated
    rms_before: dict[str, float]
    rms_after: dict[str, float]


@dataclass
class Diagnosis:
    """Result of :func:`diagnose`; :meth:`to_json` is ``diagnosis.json`` (shared/spec/diagnosis.md).

    Attributes
    ----------
    alignment : dict
    effects : list of dict
    unexplained : list of dict
    rms_before, rms_after : dict
    machine : Machine
        The parameter set extended with the effects found and refitted.
    provenance : dict
        Dotted key -> source text of the changed values.
    holdout : dict or None
        ``{"case": ..., "rms_before": ..., "rms_after": ...}`` of a held-out case.
    log : list of str
        Selection and refit log.
    notes : list of str
        What was not diagnosed and why (e.g. a cutting effect the force sampling cannot resolve); in
        ``report.md`` under "Not diagnosed" and in ``log``.
    """

    alignment: dict[str, Any]
    effects: list[dict[str, Any]]
    unexplained: list[dict[str, Any]]
    rms_before: dict[str, float]
    rms_after: dict[str, float]
    machine: Machine
    provenance: dict[str, str]
    model_text: str = "extended parameter set written to DIR/machine.toml"
    holdout: dict[str, Any] | None = None
    log: list[str] = field(default_factory=list)
    noise: dict[str, float] = field(default_factory=dict)
    results: list[CaseResult] = field(default_factory=list, repr=False)
    final_model: Model = field(default_factory=dict)
    case_name: str = ""
    cutting: CuttingResult | None = field(default=None, repr=False)
    notes: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        """The ``diagnosis.json`` object, exactly the layout of the spec."""
        return {
            "alignment": self.alignment,
            "effects": self.effects,
            "unexplained": self.unexplained,
            "rms_before": self.rms_before,
            "rms_after": self.rms_after,
            "model": self.model_text,
        }

    def write(self, out: str | Path, plots: bool = True) -> dict[str, Path]:
        """Write ``diagnosis.json``, ``machine.toml``, ``report.md`` (and ``holdout.json``) and plots."""
        from .report import write_outputs

        return write_outputs(self, Path(out), plots=plots)


def _r(x: float, digits: int = 6) -> float:
    return float(f"{x:.{digits}g}")


def _offset_s(x: float) -> float:
    """A logger offset for the report [s]: 7 significant digits, and never coarser than 1 µs.

    Seven significant digits of a logger clock in Unix time (1.7e9 s) are 1000 s: the offset came out as
    1764300000.0 for 1764300003.209287.
    """
    return min(_r(x, 7), round(float(x), 6), key=lambda v: abs(v - float(x)))  # the nearer of the two


def as_case(item: str | Path | Case) -> Case:
    """A :class:`Case` from a folder, a ``case.toml`` path or a Case."""
    return item if isinstance(item, Case) else load_case(item)


#: Fewest samples a recording needs to be diagnosed (the clock alignment differentiates positions).
MIN_SAMPLES = 3


def _read(case: Case) -> Recording:
    if case.recording is None:
        raise DiagnosisError(f"{case.source or case.folder}: the case needs a recording (recording = \"...\" in "
                             "case.toml, columns per shared/spec/recording.md)")
    if not Path(case.recording).is_file():
        raise DiagnosisError(f"{case.recording}: recording file not found; the case needs a recording there "
                             f"(named by recording = \"...\" in {case.source or case.folder})")
    problem = missing_file(case, "program")
    if problem is not None:
        raise DiagnosisError(f"{problem}; the diagnosis runs the program that made the recording")
    try:
        recording = Recording.read_csv(case.recording)
    except RecordingError as exc:
        raise DiagnosisError(str(exc)) from None
    if len(recording) < MIN_SAMPLES:
        raise DiagnosisError(f"{case.recording}: the recording has {len(recording)} sample(s); a diagnosis needs at "
                             f"least {MIN_SAMPLES} (rows below the header)")
    return recording


def _lead_mm(machine: Machine, axis: str) -> float:
    return float(machine.si(f"axis.{axis}")["screw_lead"]) * 1e3


def _start_model(choices: dict[str, list[Choice]]) -> tuple[Model, list[Parameter]]:
    """Start values and free parameters of the refit from the selection's linear coefficients."""
    model: Model = {}
    free: list[Parameter] = []
    for a, chosen in choices.items():
        am = model.setdefault(a, {})
        for ch in chosen:
            e, c, fixed = ch.variant.effect, ch.coefficients, dict(ch.variant.fixed)
            if e == "screw_compliance":
                comp = max(c["compliance_um_per_N"], 1e-6)
                am[e] = {"stiffness_N_per_um": 1.0 / comp}
                free.append(Parameter(a, e, "stiffness_N_per_um"))
                continue
            if e == "current_saturation":
                am[e] = {"limit_A": fixed["limit_A"]}
                free.append(Parameter(a, e, "limit_A"))
                continue
            params = {**{k: v for k, v in fixed.items()}, **c}
            am[e] = params
            for k in c:
                free.append(Parameter(a, e, k))
            if e == "reversal_friction":
                free.append(Parameter(a, e, "decay_mm"))
    return model, free


def _scale_parameters(machine: Machine, axes: list[str], model: Model) -> list[Parameter]:
    free = []
    for a in axes:
        sec = machine.si(f"axis.{a}")
        model.setdefault(a, {})["servo_scales"] = {
            "Spp": float(sec["position_scale"]), "Svp": float(sec["velocity_p_scale"]),
            "Svi": float(sec["velocity_i_scale"])}
        free += [Parameter(a, "servo_scales", s) for s in ("Spp", "Svp", "Svi")]
    return free


def _rms(prep: Prepared, cols: dict[str, AxisColumns], sim: Simulated, member: int) -> dict[str, float]:
    """RMS per channel after removing the artefacts fitted for this member."""
    art = artefact_values(prep, cols, sim, member)
    out: dict[str, float] = {}
    for a, c in cols.items():
        fe = prep.fe[a][c.rows_fe] - sim.fe[a][c.rows_fe, member]
        tc = (prep.current[a][c.rows_tc] - sim.current[a][c.rows_tc, member]) if c.rows_tc.size else None
        fe_art, tc_art = _artefact_signal(c, art[a])
        out[f"{a}_fe_um"] = _r(float(np.sqrt(np.mean((fe - fe_art) ** 2))), 4)
        if tc is not None:
            out[f"{a}_tcmd_A"] = _r(float(np.sqrt(np.mean((tc - tc_art) ** 2))), 4)
    return out


def _artefact_signal(c: AxisColumns, values: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
    """The fitted artefacts as signals on the FE rows [µm] and current rows [A]."""
    nf = c.rows_fe.size
    total = np.zeros(nf + c.rows_tc.size)
    for name, v in values.items():
        total = total + v * c.artefacts[name]
    fe = total[:nf] * c.sigma_fe
    tc = total[nf:] * c.sigma_tc if c.rows_tc.size else np.zeros(0)
    return fe, tc


def _without(model: Model, axis: str, effect: str) -> Model:
    out = {a: {e: dict(p) for e, p in m.items()} for a, m in model.items()}
    out[axis].pop(effect, None)
    return out


def _confidence(delta_bic: float) -> float:
    """Posterior probability of the effect from the BIC difference (Schwarz approximation of the Bayes factor)."""
    if delta_bic > 40:
        return 0.999
    return _r(min(0.999, 1.0 / (1.0 + math.exp(-0.5 * delta_bic))), 3)


def _report_params(effect: str, params: dict[str, float]) -> dict[str, float]:
    from .library import EFFECT_PARAMETERS

    names = EFFECT_PARAMETERS[effect]
    return {k: _r(float(params.get(k, 0.0)), 5) for k in names}


TIMING_EFFECTS = ("servo_delay", "velocity_feedforward")


def _timing_effects(model: Model) -> bool:
    return any(e in TIMING_EFFECTS for m in model.values() for e in m)


def _replay_of(prep: Prepared, base: Model) -> Callable[[dict, int], Simulated]:
    """``replay(disturbance, batch)``: the baseline model replayed under per-member loads."""
    def replay(disturbance: dict, batch: int) -> Simulated:
        return simulate(prep.machine, prep.t, prep.commands, [base] * batch, prep.t_start,
                        twin=prep.twin_commands(), disturbance=disturbance, start=prep.start)
    return replay


#: A scale error of a current channel is taken only within these bounds (else the scale candidate is ignored).
CHANNEL_SCALE_BOUNDS = (0.5, 2.0)


def _library_and_selection(prep: Prepared, base: Model, lead: dict[str, float], vertical: tuple[str, ...],
                           log: list[str], channel_scales: bool
                           ) -> tuple[dict[str, AxisColumns], Simulated, dict[str, Selection]]:
    """Library columns (held current of loaded holds left out) and the selection of every axis."""
    cols, base_sim = build(prep, base, lead, vertical, channel_scales=channel_scales)
    stuck = leave_out_held_current(prep.t, cols, base_sim, prep.disturbance, machine=prep.machine,
                                   replay=_replay_of(prep, base))
    if stuck:
        log.append("held current of loaded axes left out (holds, with a breakaway artefact at each end): "
                   + ", ".join(f"{a}: {n} stretches" for a, n in stuck.items()))
    selections: dict[str, Selection] = {}
    for a, c in cols.items():
        selections[a] = select(c.y, c.artefacts, c.variants, c.columns, rows=c.y.size + c.rows_left_out)
        log += [f"[{a}] {line}" for line in selections[a].log]
    return cols, base_sim, selections


def _channel_scales(selections: dict[str, Selection]) -> dict[str, float]:
    """Axis -> scale error of its current channel, where the selection took the scale candidate."""
    out = {}
    for a, sel in selections.items():
        for ch in sel.choices:
            if ch.variant.effect == CHANNEL_SCALE:
                value = 1.0 + ch.coefficients["scale_minus_1"]
                if CHANNEL_SCALE_BOUNDS[0] < value < CHANNEL_SCALE_BOUNDS[1]:
                    out[a] = value
    return out


def _name_and_refit(prep: Prepared, base: Model, lead: dict[str, float], vertical: tuple[str, ...],
                    machine: Machine, refit_scales: bool, say: Callable[[str], None], log: list[str]
                    ) -> tuple[dict[str, AxisColumns], dict[str, Selection], dict[str, list[Choice]], RefitResult,
                               Simulated]:
    """Library columns, selection per axis, the joint refit (steps 2-4 of the pipeline) and the library's
    replay (member 0: ``base``)."""
    say("building the effect library (batched replay)")
    cols, base_sim, selections = _library_and_selection(prep, base, lead, vertical, log, channel_scales=True)
    scales = _channel_scales(selections)
    if scales:
        # alignment before physics: a current logged with a scale error is corrected, then the effects are
        # selected again on the corrected current (without the scale candidates)
        for a, value in scales.items():
            prep.correct_current_scale(a, value)
        log.append("current channel scale errors (recording artefacts, corrected before naming effects): "
                   + ", ".join(f"{a}_tcmd_A x{v:.5g}" for a, v in scales.items()))
        say("rebuilding the effect library on the corrected current")
        cols, base_sim, selections = _library_and_selection(prep, base, lead, vertical, log, channel_scales=False)
    choices = {a: s.choices for a, s in selections.items()}
    start, free = _start_model(choices)
    for a in prep.axes:
        start.setdefault(a, {})
    if refit_scales and any(choices.values()):
        free += _scale_parameters(machine, [a for a in prep.axes if choices[a]], start)
    if any(choices.values()):
        # without recorded commands the program clock is known only through the block transitions and
        # the current ripple: refit the command timing with the effects (a shift mimics feed-forward)
        for a in prep.axes:
            if not prep.ref_recorded[a] and choices[a]:
                start[a]["command_shift"] = {"shift_ms": 0.0}
                free.append(Parameter(a, "command_shift", "shift_ms"))
    say(f"refitting {len(free)} parameters")
    fit = refit(prep, cols, start, free)
    log += fit.log
    return cols, selections, choices, fit, base_sim


def _timing_check(prep: Prepared, cols: dict[str, AxisColumns], final: Model, fit: RefitResult) -> float | None:
    """A servo-clock phase that explains timing effects (delay, feed-forward) as well as they do, or None.

    The servo phase is an alignment quantity: recorded commands fix it only when the machine
    interpolates as the twin does, the current ripple only up to a servo delay. Removing the delay, the
    feed-forward or both (and the scale factors refitted with them), the model is replayed at the other
    :data:`prepare.PHASE_STEPS` - 1 trial phases; if one of them comes within the minimum gain of the
    model with the timing effects, the phase is the better explanation (alignment before physics).
    """
    from .prepare import PHASE_STEPS

    proj = fit.projectors or projectors(cols)
    twin = prep.twin_commands()
    present = [e for e in TIMING_EFFECTS if any(e in m for m in final.values())]
    subsets = [(e,) for e in present] + ([tuple(present)] if len(present) > 1 else [])
    alternatives = [{a: {e: dict(p) for e, p in m.items() if e not in sub + ("servo_scales",)}
                     for a, m in final.items()} for sub in subsets]
    sim = simulate(prep.machine, prep.t, prep.commands, [final], prep.t_start, twin=twin, disturbance=prep.disturbance,
                   start=prep.start)
    r = residuals(prep, cols, sim, 0, proj)
    cost_with = float(r @ r)
    n = r.size
    tp = float(prep.machine.si("servo")["position_loop_period"])
    best = (np.inf, 0.0, 0)
    for k in range(1, PHASE_STEPS):
        phase = tp * k / PHASE_STEPS
        phase = phase - tp if phase > tp / 2 else phase
        s = simulate(prep.machine, prep.t, prep.commands, alternatives, prep.t_start + phase, twin=twin,
                     disturbance=prep.disturbance, start=prep.start)
        for j in range(len(alternatives)):
            rr = residuals(prep, cols, s, j, proj)
            best = min(best, (float(rr @ rr), phase, j))
    cost, phase, j = best
    if cost > cost_with + MIN_GAIN * n:
        # the remaining parameters were refitted with the timing effects: refit them at that phase
        removed = subsets[j]
        free = [p for p in fit.parameters if p.effect not in removed]
        start = {a: {e: dict(p) for e, p in m.items() if e not in removed} for a, m in final.items()}
        saved = prep.t_start
        prep.t_start = saved + phase
        try:
            trial = refit(prep, cols, start, free, max_iterations=5)
        finally:
            prep.t_start = saved
        cost = trial.cost_end
    if cost <= cost_with + MIN_GAIN * n:
        return phase
    return None


def _evaluate_case(name: str, prep: Prepared, base: Model, final: Model, lead: dict[str, float],
                   cols: dict[str, AxisColumns] | None = None) -> CaseResult:
    if cols is None:
        cols, base_sim = build(prep, base, lead)
        leave_out_held_current(prep.t, cols, base_sim, prep.disturbance, machine=prep.machine,
                               replay=_replay_of(prep, base))
    sim = simulate(prep.machine, prep.t, prep.commands, [base, final], prep.t_start, twin=prep.twin_commands(),
                   disturbance=prep.disturbance, start=prep.start)
    return CaseResult(name, prep, cols, sim, _rms(prep, cols, sim, 0), _rms(prep, cols, sim, 1))


def diagnose(
    case: str | Path | Case,
    holdout: str | Path | Case | None = None,
    machine: str | Path | Machine | None = None,
    axes: list[str] | None = None,
    vertical: tuple[str, ...] = ("z",),
    refit_scales: bool = True,
    progress: Callable[[str], None] | None = None,
    cutting: bool | None = None,
    drives: bool = True,
) -> Diagnosis:
    """Diagnose a case: where the recording disagrees with the twin, and which missing physics explains it.

    Parameters
    ----------
    case : case folder, ``case.toml`` or Case
        Program and recording (columns per shared/spec/recording.md; at least
        ``t_s`` and ``{a}_mm`` of a moving axis; ``{a}_ref_mm``,
        ``{a}_tcmd_A`` and ``line`` make the diagnosis sharper).
    holdout : case, optional
        A second case of the same machine, only re-simulated: RMS before /
        after with the diagnosed model (is the model general?).
    machine : name, path or Machine, optional
        Parameter set to start from (default: the case's, e.g. an identified one).
    axes : list of str, optional
        Axes to diagnose (default: every recorded axis that moves).
    vertical : tuple of str
        Axes that carry a weight (gravity candidates).
    refit_scales : bool
        Refit the scale factors Spp, Svp, Svi together with the effects.
    progress : callable, optional
        ``progress(message)``.
    cutting : bool, optional
        Diagnose the cutting process (forces ``fx_N``, ``fy_N`` and ``spindle_rpm``, effects without
        ``axis``; :mod:`.cutting`). Default: when the recording has forces and the case a stock.
    drives : bool
        Diagnose the feed drives and the controller (per axis). The recorded cutting forces load the
        replayed drives.

    Returns
    -------
    Diagnosis

    Examples
    --------
    >>> from orchestrator.diagnose import diagnose
    >>> d = diagnose("cases/z_strokes", holdout="cases/z_strokes_2")   # doctest: +SKIP
    >>> [e["effect"] for e in d.effects]                              # doctest: +SKIP
    ['gravity']
    >>> d.write("out/diag")                                           # doctest: +SKIP
    """
    say = progress or (lambda message: None)
    case = as_case(case)
    base_machine = machine if isinstance(machine, Machine) else (
        load_machine(machine) if machine is not None else case.machine)
    recording = _read(case)
    case_m = replace(case, machine=base_machine)
    do_cut = has_forces(recording, case) if cutting is None else bool(cutting)
    if do_cut and not has_forces(recording, case):
        raise DiagnosisError(f"{case.recording}: a cutting diagnosis needs 'fx_N' and 'fy_N' (at least 100 samples) "
                             f"and a [stock] in {case.source or case.folder}")
    clock, notes, only = None, [], None
    if not do_cut and needs_force_clock(recording):
        missing = [c for c in FORCE_CHANNELS if c not in recording or np.isfinite(recording[c]).sum() <= 100]
        if missing:
            hint = f"a cutting diagnosis needs {missing} too (at least 100 samples each)"
            if "fc_N" in recording:
                hint += " ('fc_N' is not enough: the cutting diagnosis compares the force components)"
        elif case.stock is None:
            hint = f"a cutting diagnosis of its forces needs a [stock] in {case.source or case.folder}"
        else:
            hint = "diagnose its cutting process (cutting=True, or leave cutting unset)"
        raise DiagnosisError(f"{case.recording}: the recording has no line and no moving position or command, so "
                             f"the feed drives cannot be diagnosed (its columns are {recording.channels}); {hint}"
                             f"{near_miss_hint(recording.channels, SPEC_COLUMNS)}")
    if do_cut and (needs_force_clock(recording) or not measures_positions(_position_rows(_cnc_rows(recording)))):
        # a dynamometer on its own clock (forces only), or forces with the controller's line or commands but no
        # actual position: aligned by its cutting load, the twin's path added
        say("aligning the dynamometer's clock by the cutting load")
        alone = needs_force_clock(recording)
        read = recording
        only = force_only_recording(case_m, recording, base_machine)
        recording, clock = only.recording, (only.offset, only.method)
        notes.append(("forces only (no line, no moving position)" if alone else
                      "forces without a measured actual position (x_mm, y_mm, z_mm): the recorded line and commands "
                      "are not used, and")
                     + " the tool path, spindle speed and lines are the twin's run with cutting at t - offset, not "
                       "measured")
        if drives:
            notes.append("drive diagnosis skipped: no measured position of the feed drives" if not alone else
                         "drive diagnosis skipped: no measured position, command or current of the feed drives")
        drives = False
    say("aligning the recording with the twin")
    forces = recorded_forces(recording)
    drive_rec = _position_rows(_cnc_rows(recording) if do_cut else recording)
    prep = prepare(case, drive_rec, base_machine, axes, disturbance=forces, clock=clock)
    log: list[str] = [f"time offset: {prep.offset:.6f} s ({prep.offset_method})", *notes]
    for a in prep.axes:  # a known column the drives do not use is said so (recording.md: never silently dropped)
        ref = f"{a}_ref_mm"
        if ref in drive_rec and not prep.ref_recorded[a] and np.isfinite(drive_rec[ref]).any():
            log.append(f"{ref} is measured on {np.isfinite(drive_rec[ref]).mean():.0%} of the rows, half or fewer: "
                       f"the twin's own commands drive the {a} servo, and {ref} is not compared")
    if prep.forces_source == "predicted":
        log.append("no fx_N/fy_N recorded: the replayed drives carry the twin's predicted cutting forces")
    elif prep.forces_source == "corrected":
        log.append("fx_N/fy_N sampled too coarsely for the tooth load: the replayed drives carry the twin's cutting "
                   "load, corrected by the recorded forces averaged over whole spindle revolutions")
    cres = None
    if do_cut and drives and prep.forces_source == "corrected":
        # forces too coarse for the tooth load: the cutting process first, then the drives carry the force
        # of the diagnosed cutting model (its spindle angle, coefficients and effects; :mod:`.cutting_load`)
        cres = _diagnose_cutting(case_m, recording, prep, say)
        if cres.data is not None:
            tick = float(base_machine.si("servo")["velocity_loop_period"])
            args = (cres, forces or {}, tick, _revolution_s(prep.nc))
            carried = {TWIN_LOAD: prep.disturbance, MODEL_TICK: model_loads(*args)}
            if prep.twin_loads is not None:
                carried[MODEL_STEP] = model_loads(*args, steps=prep.twin_loads, offset=lambda: prep.offset)
            # the diagnosed model is the periphery's (x, y): the Z drive keeps the twin's thrust in every choice
            for how in (MODEL_TICK, MODEL_STEP):
                if how in carried and prep.disturbance and "z" in prep.disturbance:
                    carried[how] = {**carried[how], "z": prep.disturbance["z"]}
            how, cost = _best_load(prep, carried)
            if how != TWIN_LOAD:
                prep.disturbance = carried[how]
                prep.forces_source = "cutting model"
                log[:] = [line for line in log if not line.startswith("fx_N/fy_N sampled too coarsely")]
                log.append("fx_N/fy_N sampled too coarsely for the tooth load: the replayed drives carry the "
                           f"diagnosed cutting model's force (refitted coefficients, effects and spindle angle), "
                           f"{how}, plus the recorded-minus-model force averaged over whole spindle revolutions")
            log.append(f"drive load chosen by the baseline replay's current residual ({cost})")
    if do_cut and only is not None:
        cres = _diagnose_cutting(case_m, recording, prep, say)
        again = _force_clock_with_effects(case_m, read, base_machine, only, cres, log)
        if again is not None:   # the diagnosis again at the clock refined with the fitted effects
            recording = again.recording
            prep = prepare(case, _position_rows(_cnc_rows(recording)), base_machine, axes,
                           disturbance=recorded_forces(recording), clock=(again.offset, again.method))
            log[0] = f"time offset: {prep.offset:.6f} s ({prep.offset_method})"
            cres = _diagnose_cutting(case_m, recording, prep, say)
    if drives:
        d = _diagnose_drives(case, prep, base_machine, holdout, vertical, refit_scales, say, log)
    else:
        d = Diagnosis({"time_offset_s": _offset_s(prep.offset), "channels": {}}, [], [], {}, {},
                      base_machine.with_values("machine", name=f"{base_machine.name}-diagnosed"), {}, log=log,
                      case_name=Path(case.folder).name)
    if do_cut:
        if cres is None:
            cres = _diagnose_cutting(case_m, recording, prep, say)
        merge_cutting(d, cres, case)
        if holdout is not None:
            say("re-simulating the held-out case (cutting)")
            hcase = as_case(holdout)
            hrec = _read(hcase)
            if has_forces(hrec, hcase):
                if needs_force_clock(hrec):   # a dynamometer on its own clock: aligned by its cutting load
                    hrec = force_only_recording(replace(hcase, machine=base_machine), hrec, base_machine).recording
                hold = holdout_cutting(replace(hcase, machine=base_machine), hrec, cres.model)
                if d.holdout is None:
                    d.holdout = {"case": str(hcase.folder), "rms_before": {}, "rms_after": {}}
                d.holdout["rms_before"].update(hold[0])
                d.holdout["rms_after"].update(hold[1])
    return d


def _force_clock_with_effects(case_m: Case, read: Recording, machine: Machine, only: ForceOnly,
                              cres: CuttingResult, log: list[str]) -> ForceOnly | None:
    """A force clock refined once more on a replay with the cutting effects ``cres`` fitted, or None.

    One outer iteration (:func:`.force_only.refine_with_effects`): the clock is refined with the fitted
    effects in the replay, and the caller refits the cutting diagnosis at that clock. None, and the first
    clock kept, when no effect was named, or none changes the replayed forces (spindle droop and chatter
    act elsewhere), or the replay fails (said in ``log``).
    """
    names = [e["effect"] for e in cres.effects]
    effects = component_values({e: p for e, p in cres.model.items() if e in names})
    if not effects:
        return None
    try:
        again = refine_with_effects(case_m, read, machine, only, effects, " and ".join(names))
    except DiagnosisError as exc:
        log.append(f"the force clock was not refined again with the fitted {' and '.join(names)} ({exc}); the "
                   f"clock of the replay without them is kept")
        return None
    log.append(f"the force clock refined again with the fitted {' and '.join(names)} in the twin's replay: "
               f"{only.offset:.6f} -> {again.offset:.6f} s ({1e3 * (again.offset - only.offset):+.3g} ms); the "
               f"cutting diagnosis refitted at that clock (one outer iteration)")
    return again


def _diagnose_cutting(case_m: Case, recording: Recording, prep: Prepared, say: Callable[[str], None]):
    """The cutting half of the diagnosis on the aligned recording (:func:`.cutting_core.diagnose_cutting`)."""
    say("diagnosing the cutting process")
    nc_t, nc_s = np.asarray(prep.nc.t, float), np.asarray(prep.nc["spindle_rpm"], float)
    offset = prep.offset
    locator = Locator(prep, {})
    return diagnose_cutting(case_m, recording, spindle_command=lambda t: np.interp(t - offset, nc_t, nc_s),
                            lines_of=locator.lines_in, unexplained_sigma=UNEXPLAINED_SIGMA, say=say)


#: The drive loads offered for forces sampled too coarsely for the tooth load (:func:`_best_load`).
TWIN_LOAD = "the twin's own load, corrected"
MODEL_TICK = "averaged over each velocity tick"
MODEL_STEP = "averaged over each communication step as the twin's drives carry it"


def _best_load(prep: Prepared, carried: dict[str, dict]) -> tuple[str, str]:
    """The cutting load of the drives whose baseline replay fits the recorded currents best.

    Offered: the twin's own predicted load corrected by the recorded forces (:func:`.prepare.corrected_forces`:
    the twin's spindle angle and its 1 ms step means), and the diagnosed cutting model's force
    (:func:`.cutting_load.model_loads`: the recording's spindle angle), averaged over each velocity tick (how
    a drive integrates the instantaneous force) or over each of the twin's communication steps (how the
    twin's drives carry their load). The twin's own run is replayed exactly only by its own load (the model
    force leaves 3e-4 A of x current over each step, 7e-3 A over each tick, where a y pitch error and a screw
    compliance were named); the independent truth, whose spindle angle is not the twin's, by the model's
    tick mean (x and y current 0.029 A rms at the baseline, against 0.092 A over steps and 0.139 A with the
    twin's load, which named a -0.03 x feed-forward on that clean 1 ms log of :mod:`.scorecard_part`).
    The baseline model is replayed with
    each, and the smallest sum of squared current residuals over the loaded axes (x, y) decides.

    Returns
    -------
    (str, str)
        The chosen key of ``carried`` and the residuals per key (A rms) for the log.
    """
    if len(carried) == 1:
        return next(iter(carried)), "not compared"
    axes = [a for a in prep.axes if a in "xy" and prep.current.get(a) is not None]
    costs = {}
    for how, dist in carried.items():
        sim = simulate(prep.machine, prep.t, prep.commands, [{}], prep.t_start, twin=prep.twin_commands(),
                       disturbance=dist, start=prep.start)
        total, count = 0.0, 0
        for a in axes:
            r = np.asarray(prep.current[a], float) - sim.current[a][:, 0]
            ok = prep.valid & np.isfinite(r)
            total += float(r[ok] @ r[ok])
            count += int(ok.sum())
        costs[how] = math.sqrt(total / count) if count else math.inf
    best = min(costs, key=costs.get)
    return best, ", ".join(f"{k}: {v:.4g} A" for k, v in costs.items())


def _revolution_s(nc: Recording) -> float:
    """One spindle revolution at the program's median running speed, s."""
    rpm = np.asarray(nc["spindle_rpm"], float)
    return 60.0 / float(np.median(rpm[rpm > 0])) if np.any(rpm > 0) else 0.01


def _position_rows(recording: Recording) -> Recording:
    """The rows with an actual position (``x_mm``, ``y_mm``, ``z_mm``) when each axis's fills half the rows or fewer.

    recording.md lets any column be empty on any row: a controller that logs positions on 2 rows of 5 (its
    currents on all) wrote a legal file, which the drive diagnosis (axes with a position on more than half
    the rows) refused. Those rows are an unevenly sampled log of the drives. Unchanged otherwise.
    """
    names = [f"{a}_mm" for a in "xyz" if f"{a}_mm" in recording]
    if not names:
        return recording
    measured = [np.isfinite(np.asarray(recording[c], float)) for c in names]
    if any(m.mean() > 0.5 for m in measured):
        return recording
    keep = np.logical_or.reduce(measured)
    if keep.sum() < MIN_SAMPLES:
        return recording
    return recording.take(keep)


def _cnc_rows(recording: Recording) -> Recording:
    """The rows of the CNC logger (any position, command, current or line cell measured), without forces."""
    names = [c for c in recording.channels if c in ("line",) or c.endswith(("_ref_mm", "_tcmd_A"))
             or c in ("x_mm", "y_mm", "z_mm")]
    keep = np.zeros(len(recording), bool)
    for c in names:
        keep |= np.isfinite(recording[c])
    if keep.all():
        return recording
    channels = {c: np.asarray(recording[c], float)[keep] for c in recording.channels if c not in ("fx_N", "fy_N",
                                                                                                   "fz_N", "fc_N")}
    lines = recording.file_lines.take(keep) if recording.file_lines is not None else None
    return Recording.from_channels(channels, source=recording.source, file_lines=lines)


def _diagnose_drives(case: Case, prep: Prepared, base_machine: Machine, holdout, vertical: tuple[str, ...],
                     refit_scales: bool, say: Callable[[str], None], log: list[str]) -> Diagnosis:
    """Steps 2-5 of the pipeline for the feed drives and the controller."""
    lead = {a: _lead_mm(base_machine, a) for a in "xyz"}
    base: Model = {a: {} for a in prep.axes}
    cols, selections, choices, fit, base_sim = _name_and_refit(prep, base, lead, vertical, base_machine,
                                                               refit_scales, say, log)
    final = fit.model
    if _timing_effects(final):
        phase = _timing_check(prep, cols, final, fit)
        if phase is not None:
            log.append(f"timing check: a servo-clock phase of {phase * 1e3:+.3f} ms explains timing effects as "
                       "well (the commands or the current ripple did not fix the phase); diagnosing again")
            prep.t_start += phase
            prep.phase_from_commands = False
            cols, selections, choices, fit, base_sim = _name_and_refit(prep, base, lead, vertical, base_machine,
                                                                       refit_scales, say, log)
            final = fit.model

    # final replay: baseline, final, and the final model without each effect (its contribution)
    effect_keys = [(a, e) for a in prep.axes for e in final.get(a, {}) if e not in PSEUDO_EFFECTS]
    twin = prep.twin_commands()
    proj = fit.projectors or projectors(cols)
    base = {a: ({"command_shift": dict(final[a]["command_shift"])} if "command_shift" in final.get(a, {}) else {})
            for a in prep.axes}
    members = [base, final] + [_without(final, a, e) for a, e in effect_keys]
    if all(not m for m in members[0].values()) and all(not m for m in final.values()):
        # nothing found: both members are the library's baseline member, replayed at this same servo phase
        sim = _repeat(base_sim, 2)
    else:
        sim = simulate(prep.machine, prep.t, prep.commands, members, prep.t_start, twin=twin,
                       disturbance=prep.disturbance, start=prep.start)
    # effects the refit made negligible are dropped (their contribution is below the minimum gain)
    kept = []
    r_final = residuals(prep, cols, sim, 1, proj)
    for k, (a, e) in enumerate(effect_keys):
        r_wo = residuals(prep, cols, sim, 2 + k, proj)
        gain = float(r_wo @ r_wo - r_final @ r_final)
        n_axis = cols[a].y.size + cols[a].rows_left_out
        if gain < MIN_GAIN * n_axis:
            log.append(f"[{a}] drop {e} after the refit: gain {gain / n_axis:.4f} n below {MIN_GAIN}")
            final[a].pop(e, None)
            continue
        kept.append((a, e))
    if len(kept) != len(effect_keys):
        effect_keys = kept
        members = [base, final] + [_without(final, a, e) for a, e in effect_keys]
        sim = simulate(prep.machine, prep.t, prep.commands, members, prep.t_start, twin=twin,
                       disturbance=prep.disturbance, start=prep.start)
    rms_before = _rms(prep, cols, sim, 0)
    rms_after = _rms(prep, cols, sim, 1)
    for a, diff in prep.nc_difference.items():
        value = _r(float(np.sqrt(np.nanmean(diff ** 2))), 4)
        rms_before[f"{a}_ref_mm"] = value
        rms_after[f"{a}_ref_mm"] = value

    locator = Locator(prep, cols)
    art = artefact_values(prep, cols, sim, 1)
    alignment = _alignment(prep, cols, art, final)
    ci_of = {(p.axis, p.effect, p.name): fit.ci90[i] for i, p in enumerate(fit.parameters)}
    effects = []
    for k, (a, e) in enumerate(effect_keys):
        choice = next(ch for ch in choices[a] if ch.variant.effect == e)
        params = _report_params(e, final[a][e])
        ci = {}
        for name in params:
            bounds = ci_of.get((a, e, name))
            if bounds is not None and np.all(np.isfinite(bounds)):
                ci[name] = [_r(float(bounds[0]), 5), _r(float(bounds[1]), 5)]
            else:
                ci[name] = [params[name], params[name]]
        where, channels = locator.effect_where(a, e, sim, 1, 2 + k, params)
        effects.append({
            "effect": e, "axis": a, "channels": channels, "where": where,
            "parameters": params, "ci90": ci, "confidence": _confidence(choice.delta_bic),
            "evidence": locator.evidence(a, e, choice, sim, 1, 2 + k, selections[a]),
        })
    effects.sort(key=lambda d: -next(ch.delta_bic for ch in choices[d["axis"]] if ch.variant.effect == d["effect"]))
    unexplained = locator.unexplained(sim, 1, art)
    for a, diff in prep.nc_difference.items():
        rms = rms_before[f"{a}_ref_mm"]
        if rms > NC_DIFFERENCE_MM:
            windows = residual_windows(prep.t, np.abs(diff) > NC_DIFFERENCE_MM, min_s=0.01)
            unexplained.append({"channels": [f"{a}_ref_mm"],
                                "where": {"time_s": windows[:10], "lines": locator.lines_in(windows),
                                          "event": "NC-kernel interpolation differs from the recorded command",
                                          "frequency_Hz": None},
                                "rms": rms})
    machine_out, provenance = extended_machine(base_machine, final, case)
    results = [CaseResult(Path(case.folder).name, prep, cols, sim, rms_before, rms_after)]
    hold = None
    if holdout is not None:
        say("re-simulating the held-out case")
        hcase = as_case(holdout)
        hrec = _read(hcase)
        hprep = prepare(hcase, _cnc_rows(hrec), base_machine, [a for a in prep.axes], disturbance=recorded_forces(hrec))
        for a, value in prep.current_scale.items():   # the same logger: the same channel scale
            if hprep.current.get(a) is not None:
                hprep.correct_current_scale(a, value)
        hres = _evaluate_case(Path(hcase.folder).name, hprep, {a: {} for a in hprep.axes},
                              {a: final.get(a, {}) for a in hprep.axes}, lead)
        results.append(hres)
        hold = {"case": str(hcase.folder), "rms_before": hres.rms_before, "rms_after": hres.rms_after}
    noise = {}
    for a, c in cols.items():
        noise[f"{a}_fe_um"] = _r(c.sigma_fe, 4)
        if c.rows_tc.size:
            noise[f"{a}_tcmd_A"] = _r(c.sigma_tc, 4)
    return Diagnosis(alignment, effects, unexplained, rms_before, rms_after, machine_out, provenance,
                     holdout=hold, log=log, noise=noise, results=results, final_model=final,
                     case_name=Path(case.folder).name)


def _repeat(sim: Simulated, count: int) -> Simulated:
    """Member 0 of ``sim`` as ``count`` identical members (every member of a batched replay is its solo run)."""
    def rep(d: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {a: np.repeat(arr[:, :1], count, axis=1) for a, arr in d.items()}
    return Simulated(rep(sim.fe), rep(sim.current), rep(sim.motor), rep(sim.force))


def _alignment(prep: Prepared, cols: dict[str, AxisColumns], art: dict[str, dict[str, float]],
               model: Model) -> dict[str, Any]:
    shift_ms = [v.get("time shift ms", 0.0) + model.get(a, {}).get("command_shift", {}).get("shift_ms", 0.0)
                for a, v in art.items()]
    offset = prep.offset + (float(np.median(shift_ms)) * 1e-3 if shift_ms else 0.0)
    channels: dict[str, dict[str, float]] = {}
    for a in prep.axes:
        if prep.ref_recorded[a]:
            channels[f"{a}_ref_mm"] = {"scale": 1.0, "offset": _r(prep.ref_offset_mm.get(a, 0.0), 6)}
        channels[f"{a}_mm"] = {"scale": 1.0, "offset": _r(art[a].get(f"{a}_mm offset", 0.0) * 1e-3, 6)}
        if prep.current[a] is not None:
            # recorded = scale x (true + offset): the offset was fitted on the current divided by the scale
            scale = prep.current_scale.get(a, 1.0)
            channels[f"{a}_tcmd_A"] = {"scale": _r(scale, 6),
                                       "offset": _r(art[a].get(f"{a}_tcmd_A offset", 0.0) * scale, 6)}
    return {"time_offset_s": _offset_s(offset), "channels": channels}


def extended_machine(base: Machine, model: Model, case: Case) -> tuple[Machine, dict[str, str]]:
    """The base parameter set with the diagnosed model: changed existing keys and ``[axis.<a>.effects]``."""
    source = (f"diagnosed: cnctwin diagnose, {_dt.date.today().isoformat()}, from {Path(case.folder).name}")
    m = base
    prov: dict[str, str] = {}

    def put(section: str, key: str, value: float) -> None:
        nonlocal m
        m = m.with_values(section, **{key: float(value)})
        prov[f"{section}.{key}"] = source

    for a, am in model.items():
        axis = f"axis.{a}"
        table = base.table(axis)
        for e, p in am.items():
            if e == "command_shift":
                continue
            if e == "servo_scales":
                for sym, key in (("Spp", "position_scale"), ("Svp", "velocity_p_scale"), ("Svi", "velocity_i_scale")):
                    put(axis, key, _r(p[sym], 6))
            elif e == "friction_mismatch":
                for d in ("positive", "negative"):
                    fr = base.table(f"{axis}.friction.{d}")
                    dc, dv = p.get("coulomb_N", 0.0), p.get("viscous_Ns_per_m", 0.0)
                    put(f"{axis}.friction.{d}", "coulomb_N", _r(max(float(fr["coulomb_N"]) + dc, 0.0), 6))
                    put(f"{axis}.friction.{d}", "static_N", _r(max(float(fr["static_N"]) + dc, 0.0), 6))
                    put(f"{axis}.friction.{d}", "viscous_Ns_per_m", _r(max(float(fr["viscous_Ns_per_m"]) + dv, 0.0), 6))
            elif e == "inertia_mismatch":
                put(axis, "mass_kg", _r(float(table["mass_kg"]) + p["mass_kg"], 6))
            elif e == "velocity_feedforward":
                put(axis, "velocity_feedforward", _r(float(table["velocity_feedforward"]) + p["gain"], 6))
            elif e == "current_saturation":
                put(axis, "peak_current_A", _r(p["limit_A"], 6))
            else:
                for key, value in machine_keys(e, p).items():
                    put(f"{axis}.effects", key, _r(value, 6))
    m = m.with_values("machine", name=f"{base.name}-diagnosed")
    return m, prov
