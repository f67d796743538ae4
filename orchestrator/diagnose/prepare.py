"""Step 1 of a diagnosis: read, align and put the recording and the twin's commands side by side."""
from __future__ import annotations

import copy
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np

from ..case import Case
from ..machine import Machine
from ..recording import Recording, RecordingError
from ..simulate import simulate as simulate_twin
from ..master import Master, MasterSettings, Probe
from ..memo import digest, remember
from ..twin import TwinOptions, build_twin, nck_parameters
from ..validation import validate_recording
from .align import (
    consensus_bracket, fill_gaps, offset_bracket_from_lines, refine_offset, refine_offset_by_axes,
    time_offset_from_lines, time_offset_from_signal,
)
from ..identify.start_state import LOG_POSITION_NOISE_M, AxisStart, estimate_start, start_window
from .errors import DiagnosisError
from .thrust_gate import thrust_bound

#: Recorded commands within this RMS of the twin's NC kernel (mm) are taken as the same interpolation.
SAME_COMMANDS_MM = 1e-3
#: An axis whose command spans less than this is not diagnosed, m.
MIN_STROKE_M = 1e-5
#: Grid of the velocity match (least squares over every lag) that aligns a recording without 'line' transitions
#: with the program, s.
ALIGN_GRID_S = 1e-3


@dataclass
class Prepared:
    """A recording aligned with the twin.

    Attributes
    ----------
    recording : Recording
    machine : Machine
    t : ndarray, shape (n,)
        Sample times on the logger clock (the replay runs on this clock), s.
    offset : float
        Logger clock minus program clock, s.
    offset_method : str
    axes : list of str
        Diagnosed axes.
    commands : dict axis -> ndarray
        Commanded positions at ``t`` [m] (recorded, else the twin's NC kernel at ``t - offset``).
    ref_recorded : dict axis -> bool
    fe : dict axis -> ndarray
        Measured following error ``cmd - actual`` [µm] (NaN where not measured).
    current : dict axis -> ndarray or None
        Measured current command [A] (NaN where not measured).
    valid : ndarray of bool
        Samples compared: from one position-loop period after ``t_start`` on (the first tick of every trial
        servo phase lies before it; earlier samples would be compared with the state held before that tick).
    line : ndarray
        Source line at each sample (recorded, else the twin's at ``t - offset``).
    nc : Recording
        The twin's own run of the program (NC kernel and servo, no cutting).
    nc_difference : dict axis -> ndarray
        Recorded minus twin commanded position [mm], offset removed (axes with a recorded command).
    ref_offset_mm : dict axis -> float
        Constant part of that difference (work offset), mm.
    t_start : float
        First servo tick of the replays: on the controller's position-loop grid
        (program time ``k Tp``) seen through the estimated offset.
    disturbance : dict axis -> callable, or None
        The recorded cutting force on the workpiece (``fx_N``, ``fy_N``) as ``f(t)`` [N]: the drives
        of the replays carry what the machine's drives carried (commanded versus actual, for loads).
        Without recorded forces, a case with a ``[stock]`` takes the twin's predicted forces
        (:func:`predicted_forces`), since the machine's drives carried a cutting load all the same.
    forces_source : str
        Where ``disturbance`` comes from: ``"recorded"``, ``"predicted"``, ``"corrected"`` (recorded forces too
        coarse for the tooth load: the twin's load corrected by them, :func:`corrected_forces`), ``"cutting
        model"`` (the diagnosed cutting model's force instead, set by :func:`.core.diagnose` when it fits the
        recorded currents better: :mod:`.cutting_load`) or ``"none"``.
    current_scale : dict axis -> float
        Scale error of a current channel found by the diagnosis (a logger artefact); ``current`` is
        already divided by it.
    start : dict axis -> AxisStart
        The motion of each axis at the recording's first sample (:func:`.identify.start_state.estimate_start`):
        the replays start from it, so that a log started while an axis moves (the usual Servo Guide log) is
        not compared with a replay catching up from rest on the command.
    twin_loads : TwinLoads or None
        The twin's own cutting load on its drives (its communication-step grid), when it was run for
        recorded forces too coarse for the tooth load.
    """

    recording: Recording
    machine: Machine
    t: np.ndarray
    offset: float
    offset_method: str
    axes: list[str]
    commands: dict[str, np.ndarray]
    ref_recorded: dict[str, bool]
    fe: dict[str, np.ndarray]
    current: dict[str, np.ndarray | None]
    valid: np.ndarray
    line: np.ndarray
    nc: Recording
    nc_difference: dict[str, np.ndarray] = field(default_factory=dict)
    ref_offset_mm: dict[str, float] = field(default_factory=dict)
    t_start: float | None = None
    phase_from_commands: bool = False
    disturbance: dict | None = None
    forces_source: str = "none"
    current_scale: dict[str, float] = field(default_factory=dict)
    start: dict[str, AxisStart] = field(default_factory=dict)
    twin_loads: "TwinLoads | None" = None

    def correct_current_scale(self, axis: str, scale: float) -> None:
        """Divide the measured current of ``axis`` by a scale error of its channel (accumulated)."""
        self.current[axis] = self.current[axis] / scale
        self.current_scale[axis] = self.current_scale.get(axis, 1.0) * scale

    def twin_commands(self) -> dict[str, Callable[[np.ndarray, float], np.ndarray]]:
        """Axis -> ``f(q, s)``: the twin's command [m] at replay-clock times ``q``, taken ``s`` seconds later.

        For the axes without a recorded command, and for recorded commands sampled more coarsely than the twin's
        interpolation (:meth:`_coarse_commands`): the twin's command plus the recorded-minus-twin difference,
        linear between the recording's samples, so that every recorded sample is kept as it is. The replays
        sample it at their own servo ticks (program time ``q - offset - s``, linear between the twin's 1 ms interpolation samples) rather than
        interpolating ``commands`` between the recording's samples: a logger sampling unevenly or slower
        than the interpolation would otherwise reshape the commands (2.6 µm rms, 157 µm at most on z for a
        random 25 % of a 1 ms log, which read as a feed-forward).
        """
        out = {}
        t_nc = np.asarray(self.nc.t, float)
        for a in self.axes:
            ref = np.asarray(self.nc[f"{a}_ref_mm"], float) * 1e-3
            if not self.ref_recorded[a]:
                out[a] = (lambda q, s, t_nc=t_nc, ref=ref: np.interp(np.asarray(q, float) - self.offset - s,
                                                                     t_nc, ref))
            elif self._coarse_commands(a):
                # recorded commands sampled more coarsely than the interpolation: the twin's command carries them
                # between the samples, corrected by the recorded-minus-twin difference (exact at every sample)
                t_rec = np.asarray(self.t, float)
                diff = self.commands[a] - np.interp(t_rec - self.offset, t_nc, ref)
                out[a] = (lambda q, s, t_nc=t_nc, ref=ref, t_rec=t_rec, diff=diff:
                          np.interp(np.asarray(q, float) - self.offset - s, t_nc, ref)
                          + np.interp(np.asarray(q, float), t_rec, diff))
        return out

    def _coarse_commands(self, a: str) -> bool:
        """Whether the recorded command of ``a`` cannot be interpolated between its samples.

        That is when it has a gap between samples longer than 1.5 twin samples, or when its samples fall
        off the twin's interpolation instants (by more than :data:`OFF_GRID` of the interpolation period).
        Interpolated between such samples, a command loses the shape of every acceleration: the twin's
        own run logged every 4 ms or 10 ms, or a random third of its 1 ms samples, read as friction,
        reversal-friction, feed-forward and inertia effects. A logger sampling every 1 ms but a quarter of a
        period after the interpolator cuts each 1 ms corner of the command by up to ``a T^2 / 8`` (1.2 µm at
        the 10 m/s^2 of a z rapid): 0.8 µm of z following-error residual on the part of
        :mod:`.scorecard_part`, named a z feed-forward of 0.008 in every run of its 1 ms loggers.
        """
        measured = np.asarray(self.t, float)[np.isfinite(np.asarray(self.recording[f"{a}_ref_mm"], float))]
        t_nc = np.asarray(self.nc.t, float)
        period = float(np.median(np.diff(t_nc))) if t_nc.size > 1 else 0.0
        if measured.size < 2 or period <= 0.0:
            return False
        if float(np.max(np.diff(measured))) > 1.5 * period:
            return True
        phase = (measured - self.offset - t_nc[0]) / period
        return bool(np.max(np.abs(phase - np.round(phase))) > OFF_GRID)


#: Largest distance of recorded command samples from the twin's interpolation instants, as a share of the
#: interpolation period, for which the recorded command is interpolated between its samples.
OFF_GRID = 0.01


def _finite_fraction(rec: Recording, name: str) -> float:
    return float(np.mean(np.isfinite(rec[name]))) if name in rec else 0.0


def _moving_axes(recording: Recording, nc: Recording, suffix: str) -> list[str]:
    """Axes whose ``{a}{suffix}`` column is mostly measured and whose commanded stroke is not negligible."""
    return [a for a in "xyz" if _finite_fraction(recording, f"{a}{suffix}") > 0.5
            and np.ptp(nc[f"{a}_ref_mm"]) > MIN_STROKE_M * 1e3]


def _has_commands(recording: Recording, nc: Recording) -> bool:
    """True when the recording carries the commanded position of an axis that moves."""
    return bool(_moving_axes(recording, nc, "_ref_mm"))


def run_key(case: Case, machine: Machine, *extra: object) -> str | None:
    """Digest of what the twin's run of ``case`` on ``machine`` depends on (program text, machine values, stock,
    tool and tool table, material, offsets; :func:`orchestrator.memo.digest`), None when the program cannot be read (the run
    then raises its own error)."""
    try:
        text = Path(case.program).read_bytes()
    except OSError:
        return None
    tools = (case.tools, case.tool_stated) if case.tools else ()  # the tool table, when the case has one
    return digest(text.decode("utf-8", errors="replace"), machine.values, str(machine.path), case.stock,
                  case.tool, case.material, case.extra, case.offsets, *tools, *extra)


def twin_commands(case: Case, machine: Machine) -> Recording:
    """The twin's run of the case's program without cutting (its NC commands, lines, servo response).

    Runs of the same content (:func:`run_key`) are done once (:func:`orchestrator.memo.remember`); each call
    gets its own copy of the recording.
    """
    def run() -> Recording:
        result = simulate_twin(case=replace(case, machine=machine), plot=False, options=TwinOptions(cutting=False))
        if len(result.recording) < 3:
            raise DiagnosisError(f"{case.program}: the twin could not run the program: {result.message}")
        return result.recording

    key = run_key(case, machine)
    return copy.deepcopy(run() if key is None else remember("twin_commands", key, run))


@dataclass(frozen=True)
class SampledForce:
    """A force recorded at times ``t`` [s], linear between samples and 0 outside: ``f(q)`` [N]."""

    t: np.ndarray
    f: np.ndarray

    def __call__(self, q: np.ndarray) -> np.ndarray:
        return np.interp(q, self.t, self.f, left=0.0, right=0.0)

    def samples_per_period(self, period_s: float) -> float:
        """Median samples per ``period_s``."""
        return period_s / float(np.median(np.diff(self.t))) if self.t.size > 2 else float("inf")


def recorded_forces(recording: Recording) -> dict[str, SampledForce] | None:
    """``{axis: f(t)}`` from ``fx_N`` / ``fy_N`` / ``fz_N`` (linear between samples, 0 outside), or None without
    forces. ``fz_N`` (the thrust on the workpiece) loads the Z drive as the twin's ``fz`` does (``Fd = fz``,
    :mod:`orchestrator.twin`)."""
    out = {}
    t = np.asarray(recording.t, float)
    for a in "xyz":
        name = f"f{a}_N"
        if name in recording:
            f = np.asarray(recording[name], float)
            ok = np.isfinite(f)
            if ok.sum() > 10:
                out[a] = SampledForce(t[ok], f[ok])
    return out or None


#: Simulated-time limit of the twin's run for the drive loads, s (``simulate``'s default).
TWIN_TIME_LIMIT_S = 3600.0
#: Outputs of the twin's cutting component that its feed drives carry (``disturbance_force``): the step-mean
#: x and y forces and the end edges' thrust (already a step mean; ``Fd = fz`` on the Z slide, see
#: :mod:`orchestrator.twin`). Without the thrust a log with plunges into the stock read as a Z weight.
DRIVE_LOADS = {"x": "cutting.fx_mean", "y": "cutting.fy_mean", "z": "cutting.fz"}
#: A drive load that never reaches this is left out, N. The Z lag's last micrometres while a slot's X feed
#: enters the stock give the twin a thrust of at most 1.7 mN on the scorecard part (0.003 mA on Z); carried,
#: any nonzero load made the Z holds' current rows leave the fit (``rest.leave_out_held_current``) and moved a
#: 40 N weight from 40.00 to 40.24 N on its 2 ms log. 0.1 N is 0.2 mA, far below a logger's current noise.
NEGLIGIBLE_LOAD_N = 0.1


def predicted_forces(case: Case, machine: Machine, offset: Callable[[], float]) -> dict | None:
    """``{axis: f(t)}``: the cutting load the twin's feed drives carry, on the logger clock [N].

    For recordings of a cutting program without a dynamometer (a servo log: positions and currents
    only): the machine's drives carried the cutting load, so the replays must carry it too, else the
    load shows up as friction or inertia. The replays are the twin's servo loops, so they carry the
    load as the twin's drives do (:func:`_carried_step_mean`): the cutting component's force on the
    workpiece averaged over a communication step (``fx_mean``, ``fy_mean``, and the thrust ``fz`` on Z:
    plunges and drilling cycles into the stock). Not the instantaneous
    ``fx_N`` at the step ends: with a 2-flute tool at 6000 rpm the tooth load repeats every 5 ms, and
    1 ms samples of it, interpolated, are another force (on the short part's servo log they moved the
    identified X velocity gain by 3 %). ``offset()`` is read at every call (the servo-phase alignment
    refines it after this is built). None when the program does not cut the case's stock.
    """
    loads = twin_loads(case, machine)
    if loads is None:
        return None
    return {a: (lambda q, a=a: loads.carried(a, np.asarray(q, float) - offset())) for a in loads.mean}


@dataclass
class TwinLoads:
    """The twin's cutting loads on its drives (x, y, and the thrust on z), every communication step of its run.

    Attributes
    ----------
    t0, h : float
        Time of sample 0 and the step, s (program clock).
    mean, instant : dict axis -> ndarray (n,)
        Step mean of the force (what the drive carries) and its instantaneous value at the step end, N.
    rate, stale : dict axis -> int
        The drive's ticks per step, and how many of them run before the cutting component in a step.
    """

    t0: float
    h: float
    mean: dict[str, np.ndarray]
    instant: dict[str, np.ndarray]
    rate: dict[str, int]
    stale: dict[str, int]

    def carried(self, a: str, q: np.ndarray) -> np.ndarray:
        """The load the twin's drive ``a`` carries at program times ``q`` [N]."""
        return _carried_step_mean(q, self.t0, self.h, self.rate[a], self.stale[a], self.mean[a])

    def instant_at(self, a: str, q: np.ndarray) -> np.ndarray:
        """The instantaneous force at program times ``q`` (linear between step ends, 0 outside) [N]."""
        grid = self.t0 + self.h * np.arange(self.instant[a].size)
        return np.interp(q, grid, self.instant[a], left=0.0, right=0.0)


def twin_loads(case: Case, machine: Machine) -> TwinLoads | None:
    """Run the twin with cutting and keep the loads on its drives (:data:`DRIVE_LOADS`); None when nothing is cut.

    An axis whose load stays below :data:`NEGLIGIBLE_LOAD_N` throughout (z without a plunge into the stock) is
    left out. Runs of the same content (:func:`run_key`) are done once (:func:`orchestrator.memo.remember`):
    the result is shared, not to be modified."""
    key = run_key(case, machine)
    if key is None:
        return _twin_loads(case, machine)
    return remember("twin_loads", key, lambda: _twin_loads(case, machine))


def _twin_loads(case: Case, machine: Machine) -> TwinLoads | None:
    twin = build_twin(replace(case, machine=machine), batch=1)
    if twin.cutting is None:
        return None
    cutting = DRIVE_LOADS["x"].split(".")[0]
    probes = [Probe(f"{a}_load_N", ref, "N") for a, ref in DRIVE_LOADS.items()]
    probes += [Probe(f"{a}_force_N", f"{cutting}.f{a}", "N") for a in DRIVE_LOADS]
    settings = MasterSettings(step=twin.options.step, time_limit=TWIN_TIME_LIMIT_S, stop_when=twin.stop_when,
                              limits=twin.limits or {})
    master = Master(twin.system, settings, probes)
    run = master.run()
    if not run.success:
        raise DiagnosisError(f"{case.program}: the twin's run with cutting, for the load on the drives, failed: "
                             f"{run.message}")
    loads = TwinLoads(float(run.recording.t[0]), float(twin.options.step), {}, {}, {}, {})
    for a in DRIVE_LOADS:
        drive = f"{a}_drive"
        mean = np.asarray(run.recording[f"{a}_load_N"], float)
        if np.max(np.abs(mean), initial=0.0) >= NEGLIGIBLE_LOAD_N:
            loads.mean[a] = mean
            loads.instant[a] = np.asarray(run.recording[f"{a}_force_N"], float)
            loads.rate[a] = int(twin.system.rates[drive])
            # the cutting component steps once a step (rate 1, the twin's), at the first fine tick: the drive's
            # first tick runs before it when the drive comes first in the execution order
            loads.stale[a] = 1 if master.order.index(drive) < master.order.index(cutting) else 0
    return loads if loads.mean else None


#: Force samples per tooth period below which the recorded forces are too coarse to carry the drive load:
#: interpolated, they are another force (see :func:`corrected_forces`).
MIN_FORCE_SAMPLES_PER_TOOTH = 6.0
#: Spindle revolutions over which the measured-minus-predicted force is averaged (:func:`corrected_forces`).
CORRECTION_REVOLUTIONS = 2


def corrected_forces(measured: dict[str, SampledForce], loads: TwinLoads, offset: Callable[[], float],
                     revolution_s: float) -> dict:
    """``{axis: f(t)}``: the twin's carried load plus the slow part of what the dynamometer measured beyond it.

    A dynamometer sampled at fewer than :data:`MIN_FORCE_SAMPLES_PER_TOOTH` samples per tooth period aliases
    the tooth load (1 ms samples of a 2-flute tool at 6000 rpm: 5 per tooth), and linear interpolation
    between its samples is another force than the one the drive carried. The drives then carry the twin's
    step-mean load, corrected by the measured-minus-predicted force averaged over
    :data:`CORRECTION_REVOLUTIONS` spindle revolutions (the tooth phase cancels over whole revolutions): a
    load that differs from the model's (wear, an edge force, another Kt) still loads the drives; the tooth
    pattern within a revolution is the twin's. On the twin's own run the correction is 0 and the replay is the
    twin's exactly. ``offset()`` is read at every call, as in :func:`predicted_forces`.
    """
    out = {}
    for a in loads.mean:
        if a not in measured:   # e.g. the thrust of a dynamometer without fz_N: the twin's own load
            out[a] = lambda q, a=a: loads.carried(a, np.asarray(q, float) - offset())
            continue
        force = measured[a]
        window = max(1, int(round(force.samples_per_period(CORRECTION_REVOLUTIONS * revolution_s))))

        def load(q, a=a, force=force, window=window):
            off = offset()
            diff = force.f - loads.instant_at(a, force.t - off)
            slow = np.convolve(diff, np.ones(window) / window, mode="same")
            return loads.carried(a, np.asarray(q, float) - off) + np.interp(q, force.t, slow, left=0.0, right=0.0)

        out[a] = load
    return out


def _coarse_forces(disturbance: dict | None, case: Case, nc: Recording) -> float | None:
    """The spindle revolution [s] when ``disturbance`` holds recorded forces too coarse for the tooth load of
    the case's tool (fewer than :data:`MIN_FORCE_SAMPLES_PER_TOOTH` per tooth), else None."""
    if not disturbance or case.stock is None or not all(isinstance(f, SampledForce) for f in disturbance.values()):
        return None
    rpm = np.asarray(nc["spindle_rpm"], float)
    if not np.any(rpm > 0):
        return None
    revolution = 60.0 / float(np.median(rpm[rpm > 0]))
    tooth = revolution / max(1, int(case.tool.flutes))
    if min(f.samples_per_period(tooth) for f in disturbance.values()) >= MIN_FORCE_SAMPLES_PER_TOOTH:
        return None
    return revolution


def _carried_step_mean(q: np.ndarray, t0: float, h: float, rate: int, stale: int, mean: np.ndarray) -> np.ndarray:
    """The step means of the cutting load as a drive stepping ``rate`` times a step carries them, at times ``q``.

    ``mean[k]`` is recorded at ``t0 + k h``: the mean over the step before it. In the step
    ``(t0 + k h, t0 + (k + 1) h]`` the cutting component steps once, at the start, after the drive's first
    ``stale`` ticks (Gauss-Seidel order): those carry ``mean[k]``, the later ticks the step's own
    ``mean[k + 1]``. Before the first sample 0, after the last the last.
    """
    x = (q - t0) / h
    k = np.ceil(x - 1e-9).astype(int) - 1                     # q in (t0 + k h, t0 + (k + 1) h]
    tick = np.floor((x - k) * rate + 1e-9).astype(int)        # the drive's tick within that step
    own = np.where(tick < stale, k, k + 1)
    return np.where(own < 1, 0.0, mean[np.clip(own, 0, mean.size - 1)])


def prepare(case: Case, recording: Recording, machine: Machine, axes: list[str] | None = None,
            nc: Recording | None = None, disturbance: dict | None = None,
            clock: tuple[float, str] | None = None) -> Prepared:
    """Align a recording with the twin and collect what the diagnosis compares.

    ``clock`` is ``(offset, method)`` when the offset was found elsewhere (a dynamometer's clock from
    its cutting load, :mod:`.force_only`): it is taken as is, and the servo phase from it.

    Raises
    ------
    DiagnosisError
        No ``{a}_mm`` of a moving axis, or the time offset cannot be estimated, or the recording
        does not belong to the case's program (``validate_recording``).
    """
    src = recording.source
    try:  # the recording must belong to the program (names the file, column and row)
        validate_recording(recording, case.program, nc_parameters=nck_parameters(machine))
    except RecordingError as exc:
        raise DiagnosisError(str(exc)) from None
    wanted = axes or [a for a in "xyz" if _finite_fraction(recording, f"{a}_mm") > 0.5]
    if not wanted:
        raise DiagnosisError(f"{src}: no axis has its actual position ('x_mm', 'y_mm' or 'z_mm') in more than half "
                             "of the rows; the feed-drive diagnosis compares the following error (commanded minus "
                             f"actual position); the recording has {recording.channels}")
    nc = nc if nc is not None else twin_commands(case, machine)
    t = np.asarray(recording.t, dtype=float)
    # --- time offset: block transitions first (pure timing), else velocities
    offset, method = (float(clock[0]), clock[1]) if clock is not None else (float("nan"), "")
    refined_on_positions = clock is not None
    if clock is None and "line" in recording and np.isfinite(recording["line"]).any():
        offset, matched = time_offset_from_lines(t, recording["line"], nc.t, nc["line"])
        method = f"{matched} matched block transitions"
        if matched < 2:
            offset = float("nan")
        elif not _has_commands(recording, nc):
            # without commands the transitions bound the clock only to about the logger's sample period; within
            # that bracket the positions choose (a feed-forward or a delay shifts them, but only by what the
            # bracket allows, so a fine logger keeps its clock from the transitions alone)
            lows, highs = offset_bracket_from_lines(t, recording["line"], nc.t, nc["line"])
            bracket = consensus_bracket(lows, highs)
            moving = _moving_axes(recording, nc, "_mm")
            if moving and bracket is not None and bracket[1] - bracket[0] > 1e-6:
                lo, hi = bracket
                # axis by axis, the axes that agree on one clock (an effect of one axis alone, a backlash or a
                # feed-forward, shifts that axis's positions: fitted jointly it pulled the clock by 11 µs)
                offset, used = refine_offset_by_axes(
                    t, {c: np.asarray(recording[f"{c}_mm"], float) for c in moving}, np.asarray(nc.t, float),
                    {c: np.asarray(nc[f"{c}_mm"], float) for c in moving}, 0.5 * (lo + hi),
                    span_s=0.5 * (hi - lo), step_s=(hi - lo) / 40.0, max_recentres=0)
                offset = float(np.clip(offset, lo, hi))
                method += (f"; refined on the positions of {', '.join(used)} within their {1e3 * (hi - lo):.3g} ms "
                           "bracket")
                refined_on_positions = True
    if not np.isfinite(offset):
        for suffix in ("_ref_mm", "_mm"):
            cands = _moving_axes(recording, nc, suffix)
            if cands:
                a = max(cands, key=lambda c: np.ptp(nc[f"{c}_ref_mm"]))
                # like with like: recorded commands with the twin's commands, recorded (actual) positions
                # with the twin's actual positions, which lag the commands by the servo's following error
                # (about 1/Kp, tens of ms), a lag that would otherwise become a clock offset
                twin = f"{a}_ref_mm" if suffix == "_ref_mm" else f"{a}_mm"
                measured = np.asarray(t, float)[np.isfinite(np.asarray(recording[f"{a}{suffix}"], float))]
                if measured.size < 3 or measured[-1] - measured[0] <= 2 * ALIGN_GRID_S:
                    raise DiagnosisError(
                        f"{src}: column '{a}{suffix}' is measured at {measured.size} sample(s) over "
                        f"{measured[-1] - measured[0] if measured.size else 0.0:.3g} s; aligning the recording with "
                        f"the program needs at least 3 samples over more than {2e3 * ALIGN_GRID_S:g} ms")
                offset = time_offset_from_signal(t, recording[f"{a}{suffix}"], nc.t, nc[twin], grid_s=ALIGN_GRID_S)
                method = (f"least-squares match of the velocity of {a}{suffix} with the twin's "
                          + ("command" if suffix == "_ref_mm" else "position"))
                if suffix == "_mm":  # the velocity match is good to a fraction of its 1 ms grid: refine
                    offset, used = refine_offset_by_axes(
                        t, {c: np.asarray(recording[f"{c}_mm"], float) for c in cands}, np.asarray(nc.t, float),
                        {c: np.asarray(nc[f"{c}_mm"], float) for c in cands}, offset)
                    method += f"; refined on the positions of {', '.join(used)}"
                    refined_on_positions = True
                break
    if not np.isfinite(offset):
        raise DiagnosisError(f"{src}: cannot align the recording with the program: no 'line' transitions and no "
                             "position channel that moves")
    with_ref = {} if clock is not None else {
        a: np.asarray(recording[f"{a}_ref_mm"], float) for a in _moving_axes(recording, nc, "_ref_mm")}
    if with_ref:
        offset = refine_offset(t, with_ref, np.asarray(nc.t, float),
                               {a: np.asarray(nc[f"{a}_ref_mm"], float) for a in with_ref}, offset)
        method += "; refined on the recorded commands"
    t_prog = t - offset
    commands, recorded, fe, cur = {}, {}, {}, {}
    nc_diff, ref_off = {}, {}
    for a in wanted:
        if f"{a}_mm" not in recording:
            raise DiagnosisError(f"{src}: axis {a} has no '{a}_mm' column; the recording has {recording.channels}")
        nc_cmd = np.interp(t_prog, nc.t, nc[f"{a}_ref_mm"])
        has_ref = _finite_fraction(recording, f"{a}_ref_mm") > 0.5
        cmd_mm = fill_gaps(t, recording[f"{a}_ref_mm"]) if has_ref else nc_cmd
        if np.ptp(cmd_mm) * 1e-3 < MIN_STROKE_M:
            continue
        if has_ref:
            inside = (t_prog >= nc.t[0]) & (t_prog <= nc.t[-1])
            diff = cmd_mm - nc_cmd
            ref_off[a] = float(np.median(diff[inside])) if inside.any() else 0.0
            nc_diff[a] = np.where(inside, diff - ref_off[a], np.nan)
        commands[a] = cmd_mm * 1e-3
        recorded[a] = has_ref
        fe[a] = (cmd_mm - np.asarray(recording[f"{a}_mm"], float)) * 1e3
        cur[a] = np.asarray(recording[f"{a}_tcmd_A"], float) if f"{a}_tcmd_A" in recording else None
    if not commands:
        raise DiagnosisError(f"{src}: no axis moves (commanded stroke below {MIN_STROKE_M * 1e6:g} µm); "
                             "nothing to diagnose")
    valid = np.ones(t.shape, dtype=bool)
    if not all(recorded.values()):
        valid &= (t_prog >= nc.t[0]) & (t_prog <= nc.t[-1])
    if "line" in recording and np.isfinite(recording["line"]).any():
        line = fill_gaps(t, recording["line"])
    else:
        idx = np.clip(np.searchsorted(nc.t, t_prog, side="right") - 1, 0, len(nc) - 1)
        line = np.asarray(nc["line"], float)[idx]
    tp = float(machine.si("servo")["position_loop_period"])
    t_start = float(offset + tp * np.ceil((t[0] - offset) / tp - 1e-9))
    # the replay starts from the state the log implies (:func:`starts`); what that estimate and the clock
    # alignment leave wrong decays with the position loop's time constant 1 / (Pp Spp): the samples of the
    # first such time constant (of the slowest axis) are not compared
    settle = max(start_window(machine, a) for a in commands)
    valid &= t >= t_start + tp + settle
    prep = Prepared(recording, machine, t, float(offset), method, list(commands), commands, recorded, fe, cur,
                    valid, line, nc, nc_diff, ref_off, t_start,
                    disturbance=disturbance if disturbance is not None else recorded_forces(recording),
                    start=starts(recording, list(commands), machine))
    revolution = _coarse_forces(prep.disturbance, case, nc)
    loads = twin_loads(case, machine) if revolution is not None else None
    prep.twin_loads = loads
    if loads is not None:
        prep.disturbance = corrected_forces(prep.disturbance, loads, lambda: prep.offset, revolution)
        prep.forces_source = "corrected"
    elif prep.disturbance is not None:
        prep.forces_source = "recorded"
        if "z" not in prep.disturbance and "z" in commands and case.stock is not None \
                and thrust_bound(case, machine, nc) >= 0.1 * NEGLIGIBLE_LOAD_N:
            # a dynamometer without fz_N: the Z drive carries the twin's thrust (plunges, drilling), not nothing;
            # the twin's run with cutting only when its run without descends over the stock (:mod:`.thrust_gate`)
            thrust = predicted_forces(case, machine, lambda: prep.offset)
            if thrust is not None and "z" in thrust:
                prep.disturbance = {**prep.disturbance, "z": thrust["z"]}
    elif case.stock is not None:
        prep.disturbance = predicted_forces(case, machine, lambda: prep.offset)
        prep.forces_source = "predicted" if prep.disturbance is not None else "none"
    same_commands = bool(nc_diff) and all(
        float(np.sqrt(np.nanmean(d ** 2))) < SAME_COMMANDS_MM for d in nc_diff.values())
    if refined_on_positions:
        # the positions fixed the clock (to microseconds on a clean twin run); a logger sampling at the
        # servo period sees the 1 ms current ripple aliased, so its phase search could only move the clock
        # off (by 0.06 ms on a clean twin run). A servo delay is then one with the logger offset (both shift
        # the positions), within the transitions' bracket when there is a `line`.
        prep.offset_method += "; servo phase from that offset"
    elif not (with_ref and same_commands):
        # recorded commands equal to the twin's fix the program clock, and with it the servo phase, to a
        # small fraction of a tick; otherwise (no commands, or a controller that interpolates differently)
        # only the block transitions do, to a sample period: take the phase from the current ripple.
        # A servo delay shorter than a position-loop period is then partly absorbed by that phase.
        align_servo_phase(prep)
    else:
        prep.phase_from_commands = True
    return prep


def starts(recording: Recording, axes: list[str], machine: Machine) -> dict[str, AxisStart]:
    """Axis -> its motion at the recording's first sample (:func:`.identify.start_state.estimate_start`).

    A quadratic fit of the recorded positions over one position-loop time constant (shortened while it does
    not fit within the noise), and the recorded current at rest. Replayed from rest on the command instead,
    a log cut into a 500 mm/min move starts with the table on the command, 140 µm ahead of where the loop
    holds it, and catches up over several time constants.
    """
    # at least a production log's finest position step as quantisation noise: the twin's own run logged from its
    # start unevenly (1 ms pairs every 5 ms) fitted Z, at rest 1 ms before its rapid, with 0.17 um/s; started
    # sliding, the replay named a Z pitch error and feed-forward
    t = np.asarray(recording.t, dtype=float)
    out = {}
    for a in axes:
        current = np.asarray(recording[f"{a}_tcmd_A"], dtype=float) if f"{a}_tcmd_A" in recording else None
        out[a] = estimate_start(t, np.asarray(recording[f"{a}_mm"], dtype=float) * 1e-3, current,
                                start_window(machine, a), min_noise=LOG_POSITION_NOISE_M)
    return out


#: Candidate servo-clock phases tried per position-loop period.
PHASE_STEPS = 8
#: Relative spread of the phase costs below which the current ripple is taken to say nothing about the phase.
PHASE_MIN_CONTRAST = 0.01


def _phase_cost(prep: Prepared, t_start: float) -> float:
    """High-pass (first-difference) residual power of the baseline replay started at ``t_start``."""
    from .model import simulate  # local: model imports the replay, which needs nothing from here

    sim = simulate(prep.machine, prep.t, prep.commands, [{}], t_start, twin=prep.twin_commands(),
                   disturbance=prep.disturbance, start=prep.start)
    cost = 0.0
    for a in prep.axes:
        ok = prep.valid & np.isfinite(prep.fe[a])
        d = np.diff((prep.fe[a] - sim.fe[a][:, 0])[ok])
        cost += float(np.sum(d * d)) / max(float(np.median(d * d)), 1e-12) if d.size else 0.0
        if prep.current[a] is not None:
            ok = prep.valid & np.isfinite(prep.current[a])
            d = np.diff((prep.current[a] - sim.current[a][:, 0])[ok])
            cost += float(np.sum(d * d)) / max(float(np.median(d * d)), 1e-12) if d.size else 0.0
    return cost


def align_servo_phase(prep: Prepared) -> None:
    """Put the replay's servo ticks in the controller's phase (in place: ``t_start`` and ``offset``).

    The position loop samples the command every ``Tp`` and the current
    command jumps at each of those ticks; a logger sees that ripple at a phase
    fixed by the controller's clock, which the block transitions only locate
    to a sample period. The phase is chosen among :data:`PHASE_STEPS` per
    ``Tp`` by the high-frequency residual power of the baseline replay
    (smooth physics does not move it), refined by a parabola, and the logger
    offset is then snapped to the nearest time consistent with it.
    """
    tp = float(prep.machine.si("servo")["position_loop_period"])
    phases = tp * np.arange(PHASE_STEPS) / PHASE_STEPS
    costs = np.array([_phase_cost(prep, prep.t_start + p) for p in phases])
    contrast = float((costs.max() - costs.min()) / max(costs.min(), 1e-300))
    if contrast < PHASE_MIN_CONTRAST:
        # no ripple to see (sparse or uneven samples, a clean recording): every phase fits alike, and the
        # phase that the offset already implies stays
        prep.offset_method += (f"; the current ripple does not fix the servo phase (cost contrast {contrast:.1e}), "
                               "phase from the offset")
        return
    i = int(np.argmin(costs))
    c_m, c_0, c_p = costs[i - 1], costs[i], costs[(i + 1) % PHASE_STEPS]
    den = c_m - 2.0 * c_0 + c_p
    frac = 0.5 * (c_m - c_p) / den if den > 0 else 0.0
    phase = phases[i] + float(np.clip(frac, -0.5, 0.5)) * tp / PHASE_STEPS
    t_start = prep.t_start + phase
    prep.offset = float(t_start - tp * np.round((t_start - prep.offset) / tp))
    prep.t_start = float(t_start)
    prep.offset_method += f"; servo phase from the current ripple ({PHASE_STEPS} trial phases)"
