"""Ground-truth recordings with hidden effects, implemented independently of the twin's servo code.

The diagnosis is proven on recordings whose physics it does not share: the
commanded positions come from the twin's NC kernel (a real controller's
interpolation is what it is), but the servo loop and the feed drive with its
hidden effects are a separate, small simulation written here from the
equations (:func:`_axis_kernel`):

* controller: P position loop every ``Tp``, PI velocity loop every ``Tv``,
  velocity feed-forward, integrator frozen while saturated, extra command
  delay by a sample history (not the twin's delay line);
* drive: explicit Euler velocity and trapezoidal position updates at
  ``Tv / 50`` with a Karnopp stick/slip friction model (not the twin's event-located RK4),
  gravity, spring, ripple and reversal friction evaluated at every substep;
* table: lead error, screw deflection, backlash play and thermal drift
  applied to the motor position (the same physics, coded again).

:func:`record` then plays a realistic logger: its own sample rate with
jitter, a clock offset, encoder and current quantisation, noise, and
optionally missing channels.

Effects are given as ``{axis: {effect: {parameter_with_unit: value}}}`` in
the vocabulary of ``shared/spec/diagnosis.md``, e.g.
``{"z": {"gravity": {"force_N": 600.0, "spring_N_per_mm": 0.0}}}``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np

from fmus_src.jit import njit

from ..machine import Machine
from ..recording import Recording

#: Substeps of the truth drive per velocity-loop tick.
SUBSTEPS = 50
#: Karnopp zero-velocity band [m/s].
KARNOPP_VELOCITY = 1e-7

# packed axis parameters
_P = ("kp", "kv", "ki", "kvff", "imax", "kf", "mass",
      "fc_p", "fs_p", "vs_p", "mu_p", "fc_n", "fs_n", "vs_n", "mu_n",
      "gravity", "spring", "rev_peak", "rev_decay", "ripple_amp", "ripple_period",
      "stiffness", "backlash", "pitch_slope", "pitch_amp", "pitch_period", "drift", "delay", "x0")


@njit
def _axis_kernel(ref: np.ndarray, p: np.ndarray, tv: float, ratio: int, out: np.ndarray, dist: np.ndarray) -> None:
    """Simulate one axis at the velocity-loop ticks; ``out[k] = (x_motor, x_table, i_cmd, v)`` after tick k.

    ``dist[k]`` is an external force resisting positive motion during tick k (the cutting force on the
    workpiece), N.
    """
    n = ref.shape[0]
    kp, kv, ki, kvff, imax, kf, mass = p[0], p[1], p[2], p[3], p[4], p[5], p[6]
    fc_p, fs_p, vs_p, mu_p, fc_n, fs_n, vs_n, mu_n = p[7], p[8], p[9], p[10], p[11], p[12], p[13], p[14]
    grav, spring, rpeak, rdecay, ramp, rper = p[15], p[16], p[17], p[18], p[19], p[20]
    stiff, blash, pslope, pamp, pper, drift, delay, x0 = p[21], p[22], p[23], p[24], p[25], p[26], p[27], p[28]
    tp = tv * ratio
    dt = tv / SUBSTEPS
    x = x0
    v = 0.0
    integ = 0.0
    vcmd = 0.0
    r_prev = ref[0]
    travel = 0.0
    last_dir = 0.0
    hist = np.zeros(n + 1)  # command computed at tick k is hist[k + 1]
    nut0 = x0 + pslope * x0
    if pper > 0.0:
        nut0 += pamp * math.sin(2.0 * math.pi * x0 / pper)
    table = nut0
    for k in range(n):
        if k % ratio == 0:
            vref = (ref[k] - r_prev) / tp
            r_prev = ref[k]
            vcmd = kp * (ref[k] - x) + kvff * vref
        err = vcmd - v
        trial = integ + ki * tv * err
        unsat = kv * err + trial
        if abs(unsat) > imax and unsat * err > 0.0:
            trial = integ  # frozen while saturated in the winding direction
        integ = trial
        cmd = kv * err + integ
        cmd = min(max(cmd, -imax), imax)
        hist[k + 1] = cmd
        # delayed application: command of time t_k - delay, linear between ticks
        if delay > 0.0:
            back = delay / tv
            j = int(math.floor(back))
            frac = back - j
            i1 = k + 1 - j
            i0 = i1 - 1
            c1 = hist[i1] if i1 >= 1 else 0.0
            c0 = hist[i0] if i0 >= 1 else 0.0
            applied = c1 * (1.0 - frac) + c0 * frac
        else:
            applied = cmd
        u = kf * applied
        for _ in range(SUBSTEPS):
            extra = 0.0
            if rdecay > 0.0:
                extra = rpeak * math.exp(-travel / rdecay)
            load = grav + spring * x + dist[k]
            if rper > 0.0:
                load -= ramp * math.sin(2.0 * math.pi * x / rper)
            f = u - load
            if abs(v) < KARNOPP_VELOCITY:
                if f > fs_p + extra:
                    d = 1.0
                elif f < -(fs_n + extra):
                    d = -1.0
                else:
                    v = 0.0
                    continue
            else:
                d = 1.0 if v > 0.0 else -1.0
            if d > 0.0:
                fr = fc_p + extra + (fs_p - fc_p) * math.exp(-abs(v) / vs_p) + mu_p * v
            else:
                fr = -(fc_n + extra + (fs_n - fc_n) * math.exp(-abs(v) / vs_n)) + mu_n * v
            v_new = v + dt * (f - fr) / mass
            if v_new * d < 0.0:  # friction cannot reverse the motion within a substep
                v_new = 0.0
            # trapezoidal position update: x += dt v_new (semi-implicit Euler) would lead the continuous
            # motion by dt (v_new - v_start) / 2 over a move, 0.75 µm at 0.3 m/s, seen as following error
            dx = dt * 0.5 * (v + v_new)
            x += dx
            if v_new != 0.0:
                s = 1.0 if v_new > 0.0 else -1.0
                if s != last_dir:
                    travel = 0.0
                    last_dir = s
                else:
                    travel += abs(dx)
            v = v_new
        nut = x + pslope * x
        if pper > 0.0:
            nut += pamp * math.sin(2.0 * math.pi * x / pper)
        if stiff > 0.0:
            nut -= u / stiff
        half = 0.5 * blash
        if table < nut - half:
            table = nut - half
        elif table > nut + half:
            table = nut + half
        out[k, 0] = x
        out[k, 1] = table + drift * (k + 1) * tv
        out[k, 2] = applied
        out[k, 3] = v


#: Effect parameter (spec name) -> (packed name, factor to SI).
EFFECT_PARAMETERS: dict[tuple[str, str], tuple[str, float]] = {
    ("gravity", "force_N"): ("gravity", 1.0),
    ("gravity", "spring_N_per_mm"): ("spring", 1e3),
    ("backlash", "width_um"): ("backlash", 1e-6),
    ("reversal_friction", "peak_N"): ("rev_peak", 1.0),
    ("reversal_friction", "decay_mm"): ("rev_decay", 1e-3),
    ("screw_compliance", "stiffness_N_per_um"): ("stiffness", 1e6),
    ("pitch_error", "slope_um_per_m"): ("pitch_slope", 1e-6),
    ("pitch_error", "amplitude_um"): ("pitch_amp", 1e-6),
    ("pitch_error", "period_mm"): ("pitch_period", 1e-3),
    ("thermal_drift", "rate_um_per_min"): ("drift", 1e-6 / 60.0),
    ("torque_ripple", "amplitude_N"): ("ripple_amp", 1.0),
    ("torque_ripple", "period_mm"): ("ripple_period", 1e-3),
    ("velocity_feedforward", "gain"): ("kvff", 1.0),
    ("servo_delay", "delay_ms"): ("delay", 1e-3),
    ("current_saturation", "limit_A"): ("imax", 1.0),
}


def axis_parameters(machine: Machine, axis: str, effects: Mapping[str, Mapping[str, float]] | None = None,
                    x0: float = 0.0) -> np.ndarray:
    """Packed truth parameters of one axis: the machine's values plus the hidden effects.

    ``friction_mismatch`` (``coulomb_N``, ``viscous_Ns_per_m``) and
    ``inertia_mismatch`` (``mass_kg``) are added to the machine's values.
    """
    a = machine.si(f"axis.{axis}")
    fp = machine.si(f"axis.{axis}.friction.positive")
    fn = machine.si(f"axis.{axis}.friction.negative")
    kf = float(a["torque_constant"]) * 2.0 * math.pi / float(a["screw_lead"])
    values = dict.fromkeys(_P, 0.0)
    values.update(
        kp=float(a["position_gain"]) * float(a["position_scale"]),
        kv=float(a["velocity_p_gain"]) * float(a["velocity_p_scale"]),
        ki=float(a["velocity_i_gain"]) * float(a["velocity_i_scale"]),
        kvff=float(a["velocity_feedforward"]), imax=float(a["peak_current"]), kf=kf, mass=float(a["mass"]),
        fc_p=abs(float(fp["coulomb"])), fs_p=abs(float(fp["static"])), vs_p=abs(float(fp["stribeck_velocity"])),
        mu_p=float(fp["viscous"]), fc_n=abs(float(fn["coulomb"])), fs_n=abs(float(fn["static"])),
        vs_n=abs(float(fn["stribeck_velocity"])), mu_n=float(fn["viscous"]), x0=x0,
    )
    for effect, params in (effects or {}).items():
        if effect == "friction_mismatch":
            dc = float(params.get("coulomb_N", 0.0))
            dv = float(params.get("viscous_Ns_per_m", 0.0))
            for s in ("p", "n"):
                values[f"fc_{s}"] += dc
                values[f"fs_{s}"] += dc
                values[f"mu_{s}"] += dv
            continue
        if effect == "inertia_mismatch":
            values["mass"] += float(params["mass_kg"])
            continue
        for name, value in params.items():
            key = (effect, name)
            if key not in EFFECT_PARAMETERS:
                raise KeyError(f"unknown truth effect parameter {effect}.{name}")
            packed, factor = EFFECT_PARAMETERS[key]
            if packed == "kvff":
                values[packed] += float(value) * factor
            else:
                values[packed] = float(value) * factor
    return np.array([values[k] for k in _P], dtype=float)


@dataclass
class TruthRun:
    """Tick-level truth signals of the simulated axes.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Tick end times (program clock), s: the outputs are valid there.
    t_cmd : ndarray, shape (n,)
        Tick start times, s: the command of the tick is sampled there.
    ref : dict axis -> ndarray
        Commanded position at the tick [m].
    motor, table, current : dict axis -> ndarray
        Motor position [m], table position [m], applied current command [A].
    line : ndarray
        Source line at the tick (program clock).
    """

    t: np.ndarray
    t_cmd: np.ndarray
    ref: dict[str, np.ndarray]
    motor: dict[str, np.ndarray]
    table: dict[str, np.ndarray]
    current: dict[str, np.ndarray]
    line: np.ndarray


def simulate_truth(machine: Machine, nc: Recording, effects: Mapping[str, Mapping[str, Mapping[str, float]]],
                   axes: tuple[str, ...] = ("x", "y", "z"), ref_filter_s: float = 0.0,
                   disturbance: Mapping[str, Callable[[np.ndarray], np.ndarray]] | None = None) -> TruthRun:
    """Run the independent truth servo + drive on the commanded positions of an NC run.

    Parameters
    ----------
    machine : Machine
        Nominal parameters (the truth adds ``effects``).
    nc : Recording
        A twin run (``t_s``, ``line``, ``{a}_ref_mm``); its commands are the controller's.
    effects : mapping
        Hidden effects per axis (spec vocabulary).
    axes : tuple of str
        Axes to simulate (the others are not recorded).
    ref_filter_s : float
        Extra moving-average filter of this length on the commands: the machine's
        controller interpolates differently from the twin's NC kernel (0 = same).
    disturbance : mapping axis -> callable, optional
        ``f(tick_end_times)`` -> external force on the axis during each tick [N] (the cutting
        force on the workpiece, resisting positive motion).
    """
    servo = machine.si("servo")
    tv = float(servo["velocity_loop_period"])
    ratio = int(round(float(servo["position_loop_period"]) / tv))
    t_nc = np.asarray(nc.t, dtype=float)
    n = int(math.floor((t_nc[-1] - t_nc[0]) / tv + 1e-9))
    tick = t_nc[0] + tv * np.arange(n)
    refs, motor, table, current = {}, {}, {}, {}
    for a in axes:
        samples = np.asarray(nc[f"{a}_ref_mm"], dtype=float) * 1e-3
        if ref_filter_s > 0.0:
            # the machine's interpolator: an extra moving average on its own output grid (the NC period)
            w = max(1, int(round(ref_filter_s / float(np.median(np.diff(t_nc))))))
            padded = np.concatenate([np.full(w - 1, samples[0]), samples])
            samples = np.convolve(padded, np.ones(w) / w, mode="valid")
        r = np.interp(tick, t_nc, samples)
        p = axis_parameters(machine, a, effects.get(a, {}), x0=float(r[0]))
        out = np.zeros((n, 4))
        dist = (np.asarray(disturbance[a](tick + tv), dtype=float) if disturbance and a in disturbance
                else np.zeros(n))
        _axis_kernel(r, p, tv, ratio, out, dist)
        refs[a], motor[a], table[a], current[a] = r, out[:, 0], out[:, 1], out[:, 2]
    idx = np.clip(np.searchsorted(t_nc, tick + tv, side="right") - 1, 0, t_nc.size - 1)
    return TruthRun(tick + tv, tick, refs, motor, table, current, np.asarray(nc["line"], dtype=float)[idx])


@dataclass(frozen=True)
class Recorder:
    """A logger: sample period and jitter, clock offset, quantisation, noise, missing channels.

    Attributes
    ----------
    period_s : float
        Nominal sample period, s (deliberately not a multiple of the servo tick by default).
    jitter_s : float
        Uniform jitter of each sample time, s.
    time_offset_s : float
        Logger clock minus program clock, s.
    position_noise_um, position_quantum_um : float
        Actual-position noise (std) and encoder resolution, µm.
    current_noise_A, current_quantum_A : float
        Current-command noise (std) and resolution, A.
    drop : tuple of str
        Channels not recorded (e.g. ``("z_ref_mm",)``).
    start_s, stop_s : float
        Program-clock window recorded (``stop_s`` <= 0: to the end).
    """

    period_s: float = 0.0017
    jitter_s: float = 0.0001
    time_offset_s: float = 0.8123
    position_noise_um: float = 0.3
    position_quantum_um: float = 1.0
    current_noise_A: float = 0.02
    current_quantum_A: float = 0.01
    drop: tuple[str, ...] = ()
    start_s: float = 0.0
    stop_s: float = 0.0


def _quantise(x: np.ndarray, q: float) -> np.ndarray:
    return np.round(x / q) * q if q > 0.0 else x


def record(truth: TruthRun, recorder: Recorder | None = None, seed: int = 0,
           table_offset_mm: Mapping[str, float] | None = None,
           current_offset_A: Mapping[str, float] | None = None,
           extra_position_um: Mapping[str, np.ndarray] | None = None) -> Recording:
    """Sample a truth run like a logger would.

    Parameters
    ----------
    truth : TruthRun
    recorder : Recorder, optional
    seed : int
        Seed of the jitter and noise.
    table_offset_mm, current_offset_A : mapping axis -> float, optional
        Channel offsets (recording artefacts).
    extra_position_um : mapping axis -> ndarray, optional
        An additive disturbance of the actual position at the truth ticks, µm
        (a phenomenon outside the effect table).

    Returns
    -------
    Recording
        ``t_s`` on the logger clock, ``line``, ``{a}_ref_mm``, ``{a}_mm``, ``{a}_tcmd_A``.
    """
    rec = recorder or Recorder()
    rng = np.random.default_rng(seed)
    t0 = max(float(truth.t[0]), rec.start_s)
    t1 = float(truth.t[-1]) if rec.stop_s <= 0.0 else min(rec.stop_s, float(truth.t[-1]))
    n = int((t1 - t0) / rec.period_s)
    t_prog = t0 + rec.period_s * np.arange(n) + rng.uniform(0.0, rec.jitter_s, n)
    t_prog = t_prog[t_prog <= t1]
    channels: dict[str, np.ndarray] = {"t_s": t_prog + rec.time_offset_s}
    idx = np.clip(np.searchsorted(truth.t, t_prog, side="right") - 1, 0, truth.t.size - 1)
    channels["line"] = truth.line[idx]
    for a in truth.ref:
        ref = np.interp(t_prog, truth.t_cmd, truth.ref[a]) * 1e3
        table = truth.table[a] * 1e3
        if extra_position_um and a in extra_position_um:
            table = table + np.asarray(extra_position_um[a]) * 1e-3
        pos = np.interp(t_prog, truth.t, table) + (table_offset_mm or {}).get(a, 0.0)
        pos = _quantise(pos + rng.normal(0.0, rec.position_noise_um * 1e-3, pos.size), rec.position_quantum_um * 1e-3)
        cur = np.interp(t_prog, truth.t, truth.current[a]) + (current_offset_A or {}).get(a, 0.0)
        cur = _quantise(cur + rng.normal(0.0, rec.current_noise_A, cur.size), rec.current_quantum_A)
        channels[f"{a}_ref_mm"] = ref
        channels[f"{a}_mm"] = pos
        channels[f"{a}_tcmd_A"] = cur
    for name in rec.drop:
        channels.pop(name, None)
    return Recording.from_channels(channels, source="<truth recording>")


@dataclass
class Scenario:
    """A hidden truth for the scorecard and the tests."""

    effects: dict[str, dict[str, dict[str, float]]] = field(default_factory=dict)
    recorder: Recorder = field(default_factory=Recorder)
    seed: int = 0
