"""``diagnose_cutting``: the cutting half of a diagnosis (forces and spindle speed), in the spec's format.

Called by :func:`.core.diagnose` for a case with a stock whose recording has
``fx_N`` and ``fy_N``; it returns the cutting effects (no ``axis``), the
unexplained force residuals, the RMS before / after of ``fx_N``, ``fy_N``,
``fc_N`` and ``spindle_rpm``, the alignment of the force channels and the
refitted model (``[cutting.effects]`` and the material's ``Kt``, ``Ke``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from fmus_src.cutting.component import CuttingError

from ..case import Case
from ..recording import Recording
from .cutting import (PHASE_EPS, CuttingColumns, CuttingData, CuttingModel, cutting_columns, helix_lead,
                      prepare_cutting, select_cutting, start_model)
from .cutting_chatter import ChatterFit, refit_chatter
from .cutting_library import CUTTING_CHANNELS, CUTTING_EFFECT_PARAMETERS, CUTTING_EVENTS, machine_keys
from .cutting_locate import (FORCED_MAX_HZ, ChatterPeak, alias_frequency, angle_of, chatter_search, force_unexplained,
                             windows_where)
from .cutting_refit import projector, refit_cutting, refit_droop
from .cutting_sampling import Resolution, resolution, sinusoid_amplitude, unresolved_effects
from .cutting_replay import ForceReplay
from .errors import DiagnosisError
from .select import MIN_GAIN, Selection

#: Model entries that are not effects.
NOT_EFFECTS = ("coefficients", "alignment")
#: Force effects (replayed); droop acts on spindle_rpm, chatter is spectral.
FORCE_EFFECTS = ("runout", "helix_angle", "edge_force", "tool_deflection", "tool_wear")


def _r(x: float, digits: int = 5) -> float:
    return float(f"{x:.{digits}g}")


def _confidence(delta_bic: float) -> float:
    if delta_bic > 40:
        return 0.999
    return _r(min(0.999, 1.0 / (1.0 + math.exp(-0.5 * delta_bic))), 3)


@dataclass
class CuttingResult:
    """The cutting half of a diagnosis.

    Attributes
    ----------
    effects, unexplained : list of dict
        Entries in the format of ``diagnosis.json`` (no ``axis``).
    rms_before, rms_after, noise : dict
        Per channel (``fx_N``, ``fy_N``, ``fc_N``, ``spindle_rpm``).
    alignment : dict
        ``{"channels": {...}, "spindle_angle_deg": ...}``.
    model : CuttingModel
        Refitted coefficients and effects (spec units).
    machine_values : dict
        Section -> {key: value} for the extended machine file.
    log : list of str
    data, cols, sim : for the plots (``sim`` members: 0 baseline, 1 final).
    chatter : list of ChatterPeak
    chatter_fit : ChatterFit or None
        The refitted tool mode of the strongest chatter cut (:mod:`.cutting_chatter`).
    notes : list of str
        Effects not offered because the force sampling cannot resolve their signature, and why
        (:mod:`.cutting_sampling`); also in ``log``.
    """

    effects: list[dict[str, Any]]
    unexplained: list[dict[str, Any]]
    rms_before: dict[str, float]
    rms_after: dict[str, float]
    noise: dict[str, float]
    alignment: dict[str, Any]
    model: CuttingModel
    machine_values: dict[str, dict[str, float]]
    log: list[str] = field(default_factory=list)
    data: CuttingData | None = field(default=None, repr=False)
    cols: CuttingColumns | None = field(default=None, repr=False)
    sim: ForceReplay | None = field(default=None, repr=False)
    chatter: list[ChatterPeak] = field(default_factory=list)
    droop_rows: tuple[np.ndarray, np.ndarray, np.ndarray] | None = field(default=None, repr=False)
    chatter_fit: ChatterFit | None = field(default=None, repr=False)
    notes: list[str] = field(default_factory=list)


def _offered(cols: CuttingColumns, unresolved: list[str]) -> CuttingColumns:
    """``cols`` without the candidate variants of the effects the force sampling cannot resolve."""
    cols.variants = [v for v in cols.variants if v.effect not in unresolved]
    return cols


def _without(model: CuttingModel, effect: str) -> CuttingModel:
    return {e: dict(p) for e, p in model.items() if e != effect}


@dataclass
class _Fitted:
    """One replay member on the compared rows with its alignment artefacts fitted."""

    rx: np.ndarray
    ry: np.ndarray
    mx: np.ndarray
    my: np.ndarray


def _fitted(data: CuttingData, cols: CuttingColumns, sim: ForceReplay, j: int, proj: np.ndarray | None) -> _Fitted:
    rows = cols.rows
    r = np.concatenate([data.measured[rows, 0] - sim.fx[rows, j], data.measured[rows, 1] - sim.fy[rows, j]])
    art = np.zeros_like(r)
    if proj is not None:
        coef, *_ = np.linalg.lstsq(proj, r / data.sigma, rcond=None)
        art = proj @ coef * data.sigma
    n = rows.size
    return _Fitted(r[:n] - art[:n], r[n:] - art[n:], sim.fx[rows, j] + art[:n], sim.fy[rows, j] + art[n:])


def _rms(x: np.ndarray) -> float:
    return _r(float(np.sqrt(np.mean(x * x))), 4) if x.size else 0.0


def diagnose_cutting(case: Case, recording: Recording, spindle_command: Callable | None = None,
                     lines_of: Callable[[list[list[float]]], list[int]] | None = None,
                     unexplained_sigma: float = 3.0, say: Callable[[str], None] = lambda m: None) -> CuttingResult:
    """Name and refit the cutting-process effects of a force recording (see :mod:`.cutting`).

    Parameters
    ----------
    case : Case
        Program, stock, tool and machine (material ``Kt``, ``Ke``).
    recording : Recording
        With ``fx_N``, ``fy_N``, actual positions, ``spindle_rpm`` (``spindle_ref_rpm``).
    spindle_command : callable, optional
        ``f(t_logger)`` -> the controller's ramped spindle speed [rpm] (droop reference).
    lines_of : callable, optional
        Time windows -> program lines executed there.
    unexplained_sigma : float
        Smoothed residual above this many noise floors is reported as unexplained.
    say : callable
        Progress messages.
    """
    lines_of = lines_of or (lambda windows: [])
    log: list[str] = []
    data = prepare_cutting(case, recording, spindle_command, say)
    log.append(f"cutting: {len(data.cuts.bounds)} cuts, spindle angle of tooth 0 at the first force sample "
               f"{math.degrees(data.theta0) % 360:.2f} deg (phase scan), force noise floor {data.sigma:.3g} N")
    # what the force sampling can resolve (the samples' spindle angles, before the entries and exits are drawn)
    sampling: dict[str, Resolution] = resolution(data, data.force_rows())
    unresolved = unresolved_effects(sampling)
    notes = [f"cutting: {sampling[e].text}" for e in unresolved]
    log += notes
    peaks: list[ChatterPeak] = []
    if "chatter" not in unresolved:
        # the machine file's own forces at the samples: its forced vibration, folded as the recording's is
        own = data.run([{}])
        peaks, aliases = chatter_search(data, np.column_stack([own.fx[:, 0], own.fy[:, 0]]))
    else:
        aliases = []
    for a in aliases:  # forced vibration the sampling folded off the spindle-harmonic grid: not chatter
        note = f"cutting: {a.text(data.flutes)}"
        log.append(note)
        notes.append(note)
    for p in peaks:
        where = "also in the air" if p.in_air else "only while cutting"
        log.append(f"cutting: cut {p.cut + 1}: non-harmonic peak {p.frequency:.1f} Hz, {p.amplitude:.2f} N, "
                   f"SNR {p.snr:.0f}, growth x{p.growth:.2f}, {where}")
    chatter = [p for p in peaks if not p.in_air]
    data.chatter_cuts = sorted({p.cut for p in chatter})
    cols = _offered(cutting_columns(data, say=say), unresolved)
    sel = select_cutting(cols)
    start = start_model(sel, data, cols)
    fit = refit_cutting(data, cols, start, say=say)
    # the spindle angle the refit moved to, less the delay of the force pulse a helix explains (helix_lead)
    moved = fit.model.get("alignment", {}).get("spindle_phase_deg", 0.0) - math.degrees(
        helix_lead(data, fit.model.get("helix_angle", {}).get("helix_deg", 0.0)))
    if abs(moved) > math.degrees(PHASE_EPS):
        # the refit moved the spindle angle beyond the band of samples left out at tooth entries and exits (set
        # at the scan's angle): those bands are redrawn at the refitted angle, and the columns, the selection and
        # the refit done again from there (at 1 kHz a 2-flute tool is sampled at 10 angles per revolution, and
        # the scan may land 10 deg off: samples 0.1 deg inside an exit then cut in the truth, not in the twin)
        log.append(f"cutting: the refit moved the spindle angle by {moved:.2f} deg from the phase scan's; "
                   "entries and exits redrawn there, effects selected and refitted again")
        data.theta0 += math.radians(moved)
        cols = _offered(cutting_columns(data, say=say), unresolved)
        sel = select_cutting(cols)
        start = start_model(sel, data, cols)
        fit = refit_cutting(data, cols, start, say=say)
    log += [f"[cutting] {line}" for line in sel.log]
    log += fit.log
    final = fit.model
    proj = projector(cols)
    n_rows = cols.y.size
    # final replay: baseline (aligned), final, final without each force effect
    base: CuttingModel = {}  # the machine file at the scan's phase (its own best alignment)
    keys = [e for e in final if e in FORCE_EFFECTS]
    sim = data.run([base, final] + [_without(final, e) for e in keys])
    fin = _fitted(data, cols, sim, 1, proj)
    r_final = np.concatenate([fin.rx, fin.ry]) / data.sigma
    kept = []
    for k, e in enumerate(keys):
        wo = _fitted(data, cols, sim, 2 + k, proj)
        r_wo = np.concatenate([wo.rx, wo.ry]) / data.sigma
        gain = float(r_wo @ r_wo - r_final @ r_final)
        if gain < MIN_GAIN * n_rows:
            log.append(f"[cutting] drop {e} after the refit: gain {gain / n_rows:.4f} n below {MIN_GAIN}")
            final.pop(e)
        else:
            kept.append(e)
    if kept != keys:
        keys = kept
        sim = data.run([base, final] + [_without(final, e) for e in keys])
        fin = _fitted(data, cols, sim, 1, proj)
    bef = _fitted(data, cols, sim, 0, proj)
    rows = cols.rows
    meas_fc = (np.asarray(recording["fc_N"], float)[data.rows][rows] if "fc_N" in recording
               else np.hypot(data.measured[rows, 0], data.measured[rows, 1]))
    ok_fc = np.isfinite(meas_fc)
    rms_before = {"fx_N": _rms(bef.rx), "fy_N": _rms(bef.ry),
                  "fc_N": _rms((meas_fc - np.hypot(bef.mx, bef.my))[ok_fc])}
    rms_after = {"fx_N": _rms(fin.rx), "fy_N": _rms(fin.ry), "fc_N": _rms((meas_fc - np.hypot(fin.mx, fin.my))[ok_fc])}
    noise = {"fx_N": _r(data.sigma, 4), "fy_N": _r(data.sigma, 4), "fc_N": _r(data.sigma, 4)}
    # spindle droop: linear in the spindle rows, with the final model's torque
    droop_choice = next((c for c in sel.choices if c.variant.effect == "spindle_droop"), None)
    droop_rows = None
    sp_offset = 0.0
    if data.spindle_rows.size > 20:
        k, ci, sp_offset = refit_droop(data, sim.torque[:, 1])
        t_all = np.asarray(recording.t, float)
        from .cutting import lagged_torque

        tq = np.interp(t_all[data.spindle_rows], data.t, lagged_torque(data.t, sim.torque[:, 1]))
        res0 = data.spindle_residual - np.mean(data.spindle_residual[tq < 1e-3]) if np.any(tq < 1e-3) else \
            data.spindle_residual - np.mean(data.spindle_residual)
        rms_before["spindle_rpm"] = _rms(res0)
        noise["spindle_rpm"] = _r(data.sigma_rpm, 4)
        if droop_choice is not None and k > 0:
            final["spindle_droop"] = {"rpm_per_Nm": k}
            res1 = data.spindle_residual - sp_offset + k * tq
            droop_ci = ci
        else:
            res1 = res0
            droop_ci = None
        rms_after["spindle_rpm"] = _rms(res1)
        droop_rows = (t_all[data.spindle_rows], tq, data.spindle_residual - sp_offset)
    # effects
    ci_of = {p: fit.ci90[i] for i, p in enumerate(fit.parameters)}
    choice_of = {c.variant.effect: c for c in sel.choices}
    effects: list[dict[str, Any]] = []
    f_spindle = float(np.mean(data.inputs.omega[data.cuts.mask(data.t.size)])) / (2 * math.pi)
    for k, e in enumerate(keys):
        params = {name: _r(float(final[e].get(name, 0.0))) for name in CUTTING_EFFECT_PARAMETERS[e]}
        ci = {}
        for name in params:
            b = ci_of.get((e, name))
            ci[name] = ([_r(float(b[0])), _r(float(b[1]))] if b is not None and np.all(np.isfinite(b))
                        else [params[name], params[name]])
        cx = sim.fx[:, 1] - sim.fx[:, 2 + k]
        cy = sim.fy[:, 1] - sim.fy[:, 2 + k]
        windows, lines = windows_where(data, rows, cx, cy, lines_of)
        ch = choice_of.get(e)
        effects.append({
            "effect": e, "channels": list(CUTTING_CHANNELS[e]),
            "where": {"time_s": windows, "lines": lines, "event": CUTTING_EVENTS[e],
                      "frequency_Hz": _r(f_spindle, 5) if e == "runout" else None},
            "parameters": params, "ci90": ci, "confidence": _confidence(ch.delta_bic if ch else 0.0),
            "evidence": _evidence(e, data, cols, sim, k, final, sel, ch),
            "_score": ch.delta_bic if ch else 0.0,
        })
    if "spindle_droop" in final and droop_rows is not None:
        k_d = final["spindle_droop"]["rpm_per_Nm"]
        t_sp, tq, res = droop_rows
        windows = _windows(t_sp, k_d * tq > 2 * data.sigma_rpm)
        effects.append({
            "effect": "spindle_droop", "channels": ["spindle_rpm"],
            "where": {"time_s": windows, "lines": lines_of(windows), "event": CUTTING_EVENTS["spindle_droop"],
                      "frequency_Hz": None},
            "parameters": {"rpm_per_Nm": _r(k_d)},
            "ci90": {"rpm_per_Nm": [_r(droop_ci[0]), _r(droop_ci[1])]},
            "confidence": _confidence(droop_choice.delta_bic),
            "evidence": (f"spindle_rpm falls with the cutting torque: {k_d * float(np.max(tq)):.1f} rpm at "
                         f"{float(np.max(tq)):.3f} N.m, back to the command in the air; "
                         f"BIC {-droop_choice.delta_bic:.0f}"),
            "_score": droop_choice.delta_bic,
        })
    chatter_fit = None
    if chatter:
        freq = float(np.median([p.frequency for p in chatter]))
        res = max(p.resolution for p in chatter)
        windows = [[round(float(data.t[data.cuts.bounds[p.cut][0]]), 4),
                    round(float(data.t[data.cuts.bounds[p.cut][1] - 1]), 4)] for p in chatter]
        best = max(chatter, key=lambda p: p.snr)
        harmonic = freq / best.spindle_hz
        folded = ""
        if math.isfinite(best.spacing) and best.spacing > 0:
            fs = 1.0 / best.spacing  # sampling frequency, Hz
            m = np.arange(1, int(FORCED_MAX_HZ / best.spindle_hz) + 1)
            near = np.abs(alias_frequency(m * best.spindle_hz, best.spacing) - freq)
            j = int(np.argmin(near))
            folded = (f", nor a spindle harmonic folded by the {1e3 * best.spacing:.3g} ms sampling (it does not "
                      f"follow the spindle angle; nearest alias: harmonic {int(m[j])} at "
                      f"{float(alias_frequency(m[j] * best.spindle_hz, best.spacing)):.1f} Hz)")
            folded += (f"; the spectrum reaches {0.5 * fs:.0f} Hz (Nyquist), the vibration itself may be at "
                       f"k x {fs:.1f} Hz +- {freq:.1f} Hz")
        final["chatter"] = {"frequency_Hz": freq}
        mode_text = ""
        try:
            mode = refit_chatter(data, final, best)
        except (DiagnosisError, CuttingError, FloatingPointError, np.linalg.LinAlgError) as exc:
            log.append(f"cutting: chatter mode not refitted ({exc}); only its frequency is reported")
        else:
            final["chatter"].update(natural_frequency_Hz=mode.natural_frequency_Hz,
                                    damping_ratio=mode.damping_ratio, stiffness_N_per_um=mode.stiffness_N_per_um)
            mode_text = "; " + mode.evidence()
            log.append(f"cutting: chatter mode of cut {best.cut + 1}: {mode.evidence()}")
            chatter_fit = mode
        effects.append({
            "effect": "chatter", "channels": list(CUTTING_CHANNELS["chatter"]),
            "where": {"time_s": windows, "lines": lines_of(windows), "event": CUTTING_EVENTS["chatter"],
                      "frequency_Hz": _r(freq)},
            "parameters": {"frequency_Hz": _r(freq)}, "ci90": {"frequency_Hz": [_r(freq - res), _r(freq + res)]},
            "confidence": _r(min(0.999, 1.0 - 1.0 / best.snr), 3),
            "evidence": (f"spectral peak at {freq:.1f} Hz in {len(chatter)} cut(s), {harmonic:.2f} x the spindle "
                         f"frequency (not a harmonic{folded}), {best.amplitude:.1f} N, {best.snr:.0f} x the spectral floor, "
                         f"growing x{best.growth:.2f} within the cut, absent in the air; not replayed sample by "
                         f"sample (regenerative): those cuts are left out of the force fit{mode_text}"),
            "_score": 1e9,
        })
    effects.sort(key=lambda d: -d["_score"])
    for d in effects:
        d.pop("_score")
    # unexplained: what the final model leaves (chatter cuts are explained by chatter)
    unexplained = force_unexplained(data, rows, fin.rx, fin.ry, unexplained_sigma, lines_of)
    for p in peaks:
        if p.in_air:
            log.append(f"cutting: {p.frequency:.1f} Hz is there while nothing cuts: not chatter")
    alignment = {"channels": {"fx_N": {"scale": 1.0, "offset": _r(_offset(data, cols, sim, proj, 0), 4)},
                              "fy_N": {"scale": 1.0, "offset": _r(_offset(data, cols, sim, proj, 1), 4)}},
                 "spindle_angle_deg": _r(math.degrees(data.theta0 + math.radians(
                     final.get("alignment", {}).get("spindle_phase_deg", 0.0))) % 360.0, 5)}
    if droop_rows is not None:
        alignment["channels"]["spindle_rpm"] = {"scale": 1.0, "offset": _r(sp_offset, 4)}
    machine_values = _machine_values(case, data, final)
    return CuttingResult(effects, unexplained, rms_before, rms_after, noise, alignment, final, machine_values, log,
                         data, cols, sim, chatter, droop_rows, chatter_fit, notes)


def _windows(t: np.ndarray, mask: np.ndarray) -> list[list[float]]:
    from .locate import residual_windows

    return residual_windows(t, mask, gap_s=0.1, min_s=0.02)[:10]


def _offset(data: CuttingData, cols: CuttingColumns, sim: ForceReplay, proj: np.ndarray | None, channel: int) -> float:
    """Fitted dynamometer offset of fx (0) or fy (1) on the final model, N."""
    if proj is None:
        return 0.0
    rows = cols.rows
    r = np.concatenate([data.measured[rows, 0] - sim.fx[rows, 1], data.measured[rows, 1] - sim.fy[rows, 1]])
    coef, *_ = np.linalg.lstsq(proj, r / data.sigma, rcond=None)
    names = [k for k in cols.artefacts if k in ("fx_N offset", "fy_N offset", "spindle phase drift")]
    name = "fx_N offset" if channel == 0 else "fy_N offset"
    return float(coef[names.index(name)]) if name in names else 0.0


def _machine_values(case: Case, data: CuttingData, final: CuttingModel) -> dict[str, dict[str, float]]:
    out: dict[str, dict[str, float]] = {}
    coef = final.get("coefficients", {})
    if coef:
        out[f"material.{case.material}"] = {"kt_N_per_m2": _r(coef.get("kt_N_per_m2", data.kt), 6),
                                            "ke": _r(coef.get("ke", data.ke), 6)}
    eff: dict[str, float] = {}
    for e, p in final.items():
        if e in CUTTING_EFFECT_PARAMETERS:
            eff.update({k: _r(v, 6) for k, v in machine_keys(e, p).items()})
    if eff:
        out["cutting.effects"] = eff
    return out


def _evidence(effect: str, data: CuttingData, cols: CuttingColumns, sim: ForceReplay, k: int, final: CuttingModel,
              sel: Selection, choice) -> str:
    """One sentence: the distinguishing signature, the share of residual power, the BIC change."""
    t = data.t
    share = (choice.gain / max(sel.rss_before - sel.n, 1e-9)) if choice else 0.0
    tail = (f"; explains {min(share, 1.0):.0%} of the force residual power above noise; BIC {-choice.delta_bic:.0f} "
            f"(variant {choice.variant.label})") if choice else ""
    meas = np.hypot(data.measured[:, 0], data.measured[:, 1])
    base = np.hypot(sim.fx[:, 0], sim.fy[:, 0])
    if effect == "runout":
        f_sp = float(np.mean(data.inputs.omega[data.cuts.mask(t.size)])) / (2 * math.pi)
        i0, i1 = max(data.cuts.bounds, key=lambda b: b[1] - b[0])
        theta = angle_of(data)[i0:i1]  # the spindle angle, not 2 pi f t: the samples' phase of the harmonic
        a = math.hypot(sinusoid_amplitude(theta, data.measured[i0:i1, 0]),
                       sinusoid_amplitude(theta, data.measured[i0:i1, 1]))
        a0 = math.hypot(sinusoid_amplitude(theta, sim.fx[i0:i1, 0]), sinusoid_amplitude(theta, sim.fy[i0:i1, 0]))
        if math.isfinite(a) and math.isfinite(a0):
            text = (f"force component at the spindle frequency {f_sp:.1f} Hz of {a:.1f} N measured against "
                    f"{a0:.1f} N in the twin: unequal tooth loads")
        else:
            text = (f"unequal tooth loads (the samples of the longest cut do not spread over the revolution: no "
                    f"amplitude at the spindle frequency {f_sp:.1f} Hz is given)")
    elif effect == "helix_angle":
        i0, i1 = max(data.cuts.bounds, key=lambda b: b[1] - b[0])
        tooth = angle_of(data)[i0:i1] * data.flutes  # the tooth-passing phase of each sample
        hm = (sinusoid_amplitude(2 * tooth, data.measured[i0:i1, 1])
              / max(sinusoid_amplitude(tooth, data.measured[i0:i1, 1]), 1e-12))
        hb = sinusoid_amplitude(2 * tooth, sim.fy[i0:i1, 0]) / max(sinusoid_amplitude(tooth, sim.fy[i0:i1, 0]), 1e-12)
        text = (f"the tooth pulse is smoothed: 2nd / 1st tooth-passing harmonic of fy {hm:.3f} measured against "
                f"{hb:.3f} for a straight flute")
    elif effect == "edge_force":
        p = final["edge_force"]
        text = (f"force while a tooth is engaged that does not scale with the chip: {p.get('kte_N_per_mm', 0):.2f} "
                f"N/mm tangential, {p.get('kre_N_per_mm', 0):.2f} N/mm radial per mm of depth (a Kt error scales "
                "with the chip and is refitted separately)")
    elif effect == "tool_deflection":
        parts = []
        for i0, i1 in data.cuts.bounds:
            m = np.zeros(t.size, bool)
            m[i0:i1] = True
            if base[m].mean() > 0:
                parts.append(f"{meas[m].mean() / base[m].mean():.3f}")
        text = ("the deeper the cut, the more the force falls short of the twin's (mean measured / twin force per "
                f"cut: {', '.join(parts)}), a Kt error would scale every cut alike")
    elif effect == "tool_wear":
        rate = final["tool_wear"]["rate_percent_per_min"]
        text = f"force grows with cutting time, {rate:.1f} % per minute of cutting, at constant conditions"
    else:
        text = effect
    return text + tail

