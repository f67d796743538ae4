"""Fixed-step co-simulation master.

The master advances a :class:`~orchestrator.system.System` on a fixed
communication step ``h`` (default 1 ms). Time is always computed as
``t0 + k·h`` from an integer step count, never accumulated.

Each communication step is split into ``N = lcm(rates)`` fine ticks; a
component of rate ``r`` steps at every ``N/r``-th tick with step ``h/r``.
Before a component steps, its connected inputs are refreshed:

* ``"gauss-seidel"`` (default): from the sources' *current* outputs, so a
  component stepped later in the execution order sees the outputs its
  predecessors produced in the same tick;
* ``"jacobi"``: from the outputs as they were at the start of the tick.

The run ends when the stop signal (e.g. ``"nck.done"``) is true for every
batch member, or at the time limit. A batch member fails alone, with a reason
in ``RunResult.failures``, when it diverges (NaN or inf on a connection, a
value outside ``limits``) or when a component fails it (a servo alarm, an
integrator error: :meth:`fmus_src.component.Component.fail_members`, collected
after every communication step); the other members run on. When every member
has failed, or a component raises, the run ends with ``success = False``, a
message naming the component and time, and the recording so far kept.
"""
from __future__ import annotations

import logging
import math
import sys
from dataclasses import dataclass, field
from typing import Callable, Literal, Sequence

import numpy as np

from fmus_src.component import Variable

from .errors import CncTwinError, SimulationError, SystemDescriptionError
from .recording import Recording
from .system import Connection, System, split_reference, unit_conversion, unit_text

log = logging.getLogger(__name__)

Method = Literal["gauss-seidel", "jacobi"]


@dataclass(frozen=True)
class Probe:
    """A recorded channel: a variable, a name and a unit for the recording.

    Parameters
    ----------
    channel : str
        Name in the recording (e.g. ``"x_mm"``).
    reference : str
        ``"component.variable"`` to sample.
    unit : str, optional
        Unit of the channel; the variable's value is converted to it.
        Defaults to the variable's own unit.
    """

    channel: str
    reference: str
    unit: str | None = None


def probe_conversion(system: System, probe: Probe) -> tuple[float, float]:
    """``(factor, offset)`` from the probed variable's unit to the probe's channel unit ((1, 0) without one).

    A variable without a declared unit is recorded unchanged, under the
    channel unit when the probe gives one, else with no unit (None).

    Raises
    ------
    SystemDescriptionError
        The channel unit cannot be converted from the variable's.
    """
    comp, var = split_reference(probe.reference)
    component = system.component(comp)
    declared = component.variable(var)
    if probe.unit is None or probe.unit == declared.unit:
        return 1.0, 0.0
    # a unit the component defines itself (an FMU's <Unit> or <DisplayUnit>, e.g. degF) converts with that definition
    defined = getattr(component, "unit_definition", None)
    channel = Variable(declared.name, "input", probe.unit,
                       unit_definition=defined(probe.unit) if defined is not None else None)
    return unit_conversion(declared, channel, f"probe {probe.channel!r}: {probe.reference} "
                                              f"[{unit_text(declared.unit)}] -> [{probe.unit}]")


def probe_factor(system: System, probe: Probe) -> float:
    """Factor of :func:`probe_conversion` (for paths that scale only; see there).

    Raises
    ------
    SystemDescriptionError
        The channel unit cannot be converted from the variable's, or only with an offset.
    """
    factor, offset = probe_conversion(system, probe)
    if offset != 0.0:
        raise SystemDescriptionError(f"probe {probe.channel!r}: {probe.reference} -> [{probe.unit}] needs an offset "
                                     f"({offset!r}); use probe_conversion")
    return factor


def probe_unit(system: System, probe: Probe) -> str | None:
    """Unit of the probe's channel: the probe's own, else the variable's (None: no unit declared)."""
    comp, var = split_reference(probe.reference)
    return probe.unit or system.component(comp).variable(var).unit


@dataclass
class MasterSettings:
    """Settings of a run.

    Attributes
    ----------
    step : float
        Communication step ``h``, s.
    t0 : float
        Start time, s.
    time_limit : float
        Stop at ``t0 + time_limit`` at the latest, s.
    stop_when : str, tuple of str, or None
        ``"component.variable"`` (Boolean output), or several; the run ends
        when all of them are true for all batch members.
    method : {"gauss-seidel", "jacobi"}
        Coupling scheme.
    decimation : int
        Record every ``decimation``-th communication step.
    check_every : int
        Check connections for NaN/inf (and ``limits``) every so many communication steps.
    limits : dict, optional
        ``{"component.variable": (low, high)}`` in the variable's unit: a value
        outside marks the batch member as diverged (e.g. a runaway axis).
    compiled : bool
        Run the step loop compiled (:mod:`orchestrator.compiled`) when every
        component is covered by it (all-native twins), or in C through the
        FMUs' function pointers (:mod:`orchestrator.fmu.master_loop`) when
        every component is an FMUComponent; same results bit for bit.
        False: always the Python loop.
    threads : int or None
        Threads of the compiled loop for a batch: the members are split into
        that many blocks, stepped side by side (:mod:`orchestrator.compiled.blocks`);
        same results bit for bit. None: one per core this process may use,
        with at least 4 members each. 1: one thread.
    """

    step: float = 1e-3
    t0: float = 0.0
    time_limit: float = 3600.0
    stop_when: str | tuple[str, ...] | None = None
    method: Method = "gauss-seidel"
    decimation: int = 1
    check_every: int = 50
    limits: dict[str, tuple[float, float]] = field(default_factory=dict)
    compiled: bool = True
    threads: int | None = None

    def __post_init__(self) -> None:
        if not (self.step > 0 and math.isfinite(self.step)):
            raise SystemDescriptionError(f"communication step must be positive and finite, got {self.step!r}")
        if not self.time_limit > 0:
            raise SystemDescriptionError(f"time limit must be positive, got {self.time_limit!r}")
        if self.method not in ("gauss-seidel", "jacobi"):
            raise SystemDescriptionError(f"method must be 'gauss-seidel' or 'jacobi', got {self.method!r}")
        if int(self.decimation) != self.decimation or self.decimation < 1:
            raise SystemDescriptionError(f"decimation must be a positive integer, got {self.decimation!r}")
        if self.threads is not None and (isinstance(self.threads, bool) or int(self.threads) != self.threads
                                         or self.threads < 1):
            raise SystemDescriptionError(f"threads must be None or a positive integer, got {self.threads!r}")

    def stop_signals(self) -> tuple[str, ...]:
        """The stop signals as a tuple (empty when the run goes to the time limit)."""
        if self.stop_when is None:
            return ()
        return (self.stop_when,) if isinstance(self.stop_when, str) else tuple(self.stop_when)


@dataclass
class _Wire:
    target_values: dict
    target_name: str
    source_values: dict
    source_name: str
    factor: float
    offset: float = 0.0


class _Recorder:
    """Samples probes into arrays that grow geometrically (amortised preallocation)."""

    def __init__(self, probes: list[tuple[str, dict, str, tuple[float, float], str | None]], batch: int,
                 capacity: int) -> None:
        self.probes = probes
        self.batch = batch
        self.n = 0
        self.t = np.empty(capacity)
        shape = (capacity,) if batch == 1 else (capacity, batch)
        self.buffers = [np.empty(shape) for _ in probes]

    def _grow(self) -> None:
        new = max(16, 2 * self.t.shape[0])
        self.t = np.resize(self.t, new)
        self.buffers = [np.resize(b, (new,) + b.shape[1:]) for b in self.buffers]

    def sample(self, t: float) -> None:
        if self.n == self.t.shape[0]:
            self._grow()
        self.t[self.n] = t
        for buf, (_, values, name, (factor, offset), _) in zip(self.buffers, self.probes):
            v = values[name]
            buf[self.n] = v[0] * factor if self.batch == 1 else v * factor
            if offset != 0.0:
                buf[self.n] += offset
        self.n += 1

    def recording(self, success: bool, message: str, source: str) -> Recording:
        channels = {"t_s": self.t[: self.n].copy()}
        units = {"t_s": "s"}
        for buf, (channel, _, _, _, unit) in zip(self.buffers, self.probes):
            channels[channel] = buf[: self.n].copy()
            units[channel] = unit
        return Recording.from_channels(channels, units, success, message, source)


@dataclass
class RunResult:
    """What a run returns (python-control style).

    Attributes
    ----------
    recording : Recording
        Recorded channels (batched when the system has ``B > 1``).
    success : bool
        True when the stop condition was reached (or the time limit, when
        there is no stop condition).
    message : str
        Why the run ended.
    steps : int
        Communication steps taken.
    t_end : float
        Time reached, s.
    stopped_at : ndarray, shape (B,)
        Time each member met the stop condition, s (NaN if it never did).
    failed : ndarray of bool, shape (B,)
        Members that diverged (non-finite values or outside ``limits``), that a
        component failed (alarm, integrator error) or that did not reach the stop
        signal by the time limit; the other members of a batch run on.
    failures : list of str or None
        Why each member failed (None for members that did not): ``"diverged at
        t = ... s: ..."``, ``"failed at t = ... s: <component>: ..."`` or ``"did not
        reach ... by the time limit ..."``.
    """

    recording: Recording
    success: bool
    message: str
    steps: int
    t_end: float
    stopped_at: np.ndarray = field(default_factory=lambda: np.empty(0))
    failed: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    failures: list = field(default_factory=list)


class Master:
    """Fixed-step co-simulation master for a :class:`System`.

    Parameters
    ----------
    system : System
        Components and connections.
    settings : MasterSettings, optional
        Step, time limit, stop signal, coupling method, decimation.
    probes : sequence of Probe or str, optional
        What to record; a plain ``"component.variable"`` string records that
        variable under its own name and unit.
    progress : callable, optional
        ``progress(t, t_final_estimate)`` called about every 1 % of the time limit
        or of ``expected_duration``.
    expected_duration : float, optional
        Expected simulated time, s: sizes the recorder's first allocation and
        the progress scale (the run still ends on its stop signals).
    """

    def __init__(
        self,
        system: System,
        settings: MasterSettings | None = None,
        probes: Sequence[Probe | str] = (),
        progress: Callable[[float, float], None] | None = None,
        expected_duration: float | None = None,
    ) -> None:
        self.system = system
        self.settings = settings or MasterSettings()
        self.progress = progress
        self.expected_duration = expected_duration
        if not system.components:
            raise SystemDescriptionError(f"{system.name}: the system has no components")
        self.order = system.execution_order()
        self.probes = [p if isinstance(p, Probe) else Probe(p, p) for p in probes]
        self._stop_refs = self.settings.stop_signals()
        for reference in [p.reference for p in self.probes] + list(self.settings.limits) + list(self._stop_refs):
            comp, var = split_reference(reference)
            system.component(comp).variable(var)
        for p in self.probes:  # a channel's unit must be the variable's or convertible from it
            probe_conversion(system, p)
        self._wires: dict[str, list[_Wire]] = {name: [] for name in system.components}
        self._connections_by_target: dict[str, list[Connection]] = {name: [] for name in system.components}
        for c in system.connections:
            self._connections_by_target[c.target_component].append(c)

    # ------------------------------------------------------------------ internals
    def _start(self) -> None:
        """Fresh failure bookkeeping, then every component set up; shared by the Python and the compiled loops.

        Components are set up along the signal flow: each gets its inputs from the
        components already set up (start values inside feedback loops). A failure
        here (bad program, bad parameters) is raised: there is nothing to keep yet.
        """
        comps = self.system.components
        self._failed = np.zeros(self.system.batch, dtype=bool)
        self._failures: list[str | None] = [None] * self.system.batch
        self._resolve_wires()
        try:
            for name in self.order:
                self._transfer(self._wires[name])
                comps[name].setup(self.settings.t0)
        except BaseException:
            self._terminate_all()
            raise
        self._resolve_wires()
        # components with the per-member failure channel (native ones; an FMU raises instead)
        self._reporting = [comps[name] for name in self.order if callable(getattr(comps[name], "take_failures", None))]

    def _resolve_wires(self) -> None:
        """Bind connections to the components' value dictionaries once."""
        comps = self.system.components
        for name, conns in self._connections_by_target.items():
            self._wires[name] = [
                _Wire(comps[c.target_component].values, c.target_variable,
                      comps[c.source_component].values, c.source_variable, c.factor, c.offset)
                for c in conns
            ]

    @staticmethod
    def _transfer(wires: list[_Wire], snapshot: dict[int, np.ndarray] | None = None) -> None:
        for w in wires:
            src = snapshot[id(w)] if snapshot is not None else w.source_values[w.source_name]
            dst = w.target_values[w.target_name]
            if w.factor == 1.0:
                np.copyto(dst, src, casting="unsafe")
            else:
                np.multiply(src, w.factor, out=dst, casting="unsafe")
            if w.offset != 0.0:  # affine units (degC -> K): factor, then offset, as every loop does
                np.add(dst, w.offset, out=dst, casting="unsafe")

    def _check_divergence(self, t: float) -> None:
        """Mark members with non-finite connection values or values outside the limits as failed.

        Raises
        ------
        SimulationError
            When every member has failed (for B = 1: at the first failure).
        """
        checks = []
        for name, wires in self._wires.items():
            for w, c in zip(wires, self._connections_by_target[name]):
                checks.append((c.source, w.source_values[w.source_name], None))
        for reference, bounds in self.settings.limits.items():
            comp, var = split_reference(reference)
            checks.append((reference, self.system.components[comp].values[var], bounds))
        for reference, values, bounds in checks:
            if values.dtype.kind != "f":
                continue
            bad = ~np.isfinite(values)
            if bounds is not None:
                with np.errstate(invalid="ignore"):
                    bad |= (values < bounds[0]) | (values > bounds[1])
            bad &= ~self._failed
            if not bad.any():
                continue
            for b in np.flatnonzero(bad):
                value = values[b]
                what = "is not finite" if not np.isfinite(value) else (
                    f"= {value:.6g} is outside [{bounds[0]:g}, {bounds[1]:g}]" if bounds else "")
                self._failures[b] = f"diverged at t = {t:.6f} s: {reference} {what}"
                log.warning("member %d %s", b, self._failures[b])
            self._failed |= bad
        self._raise_if_all_failed()

    def _raise_if_all_failed(self) -> None:
        """Raise :class:`SimulationError` with the first reason when no member is left."""
        if self._failed.all():
            first = next(f for f in self._failures if f)
            members = "" if self.system.batch == 1 else f" (all {self.system.batch} members; first: member {self._failures.index(first)})"
            raise SimulationError(f"simulation {first}{members}")

    def _collect_member_failures(self, raise_when_all: bool = True) -> None:
        """Move the failures the components recorded (``take_failures``) into ``failed`` / ``failures``.

        Raises
        ------
        SimulationError
            When every member has failed (and ``raise_when_all``).
        """
        found = False
        for component in self._reporting:
            for members, reason, t_fail in component.take_failures():
                for b in members:
                    if not self._failed[b]:
                        self._failures[b] = f"failed at t = {t_fail:.6f} s: {reason}"
                        log.warning("member %d %s", b, self._failures[b])
                        self._failed[b] = True
                        found = True
        if found and raise_when_all:
            self._raise_if_all_failed()

    def _terminate_all(self) -> CncTwinError | None:
        """Terminate every initialised component, the others too when one fails; the first failure is returned.

        A foreign FMU may fail in ``fmi2Terminate`` (a final check, a file it cannot
        write); that must not leave the components after it running, nor lose the
        recording of the run (see :meth:`_terminated`).
        """
        first: CncTwinError | None = None
        for name in self.order:
            component = self.system.components[name]
            if getattr(component, "state", "") == "initialized":
                try:
                    component.terminate()
                except CncTwinError as exc:
                    first = first or exc
        return first

    def _terminated(self, success: bool, message: str, problem: CncTwinError | None, t: float) -> tuple[bool, str]:
        """Success and message of a run after :meth:`_terminate_all` returned ``problem``.

        A run that succeeded fails with the termination error (every member failed,
        as for an error while stepping); a run that had failed already keeps its own
        message, with the termination error appended.
        """
        if problem is None:
            return success, message
        if success:
            return False, self._run_failed(problem, t)
        message = f"{message}; terminating then failed too: {problem}"
        log.error("%s", message)
        return False, message

    def _stop_flags(self) -> np.ndarray | None:
        if not self._stop_refs:
            return None
        flags = np.ones(self.system.batch, dtype=bool)
        for reference in self._stop_refs:
            comp, var = split_reference(reference)
            flags &= np.asarray(self.system.components[comp].values[var], dtype=bool)
        return flags

    # ---------------------------------------------- how a run ends (shared by the Python and the compiled loops)
    def _stop_message(self, t: float) -> str:
        """The message of a run ended by its stop signals at ``t``."""
        return f"{' and '.join(self._stop_refs)} at t = {t:.3f} s"

    def _time_limit_reached(self, stopped_at: np.ndarray) -> tuple[bool, str]:
        """Success and message at the time limit; members still short of the stop signals fail.

        Parameters
        ----------
        stopped_at : ndarray, shape (B,)
            Time each member met the stop signals (NaN: not yet), s.
        """
        s = self.settings
        if not self._stop_refs:
            return True, f"time limit of {s.time_limit:g} s reached"
        refs = " and ".join(self._stop_refs)
        waiting = np.flatnonzero(np.isnan(stopped_at) & ~self._failed)
        for b in waiting:
            self._failures[b] = f"did not reach {refs} by the time limit of {s.time_limit:g} s"
        self._failed[waiting] = True
        batch = self.system.batch
        success = bool(batch > 1 and not self._failed.all())
        message = f"time limit of {s.time_limit:g} s reached before {refs}"
        if success:
            message += f" for {waiting.size} of {batch} members"
        return success, message

    def _run_failed(self, exc: CncTwinError, t: float) -> str:
        """The message of a run ended by ``exc`` at ``t`` (logged); a component's error fails every member left."""
        message = str(exc) if isinstance(exc, SimulationError) else f"simulation failed at t = {t:.6f} s: {exc}"
        log.error("%s", message)
        if not isinstance(exc, SimulationError):  # a component gave up on the (rest of the) batch
            self._collect_member_failures(raise_when_all=False)
            for b in np.flatnonzero(~self._failed):
                self._failures[b] = message
            self._failed[:] = True
        return message

    def _result(self, recording: Recording, success: bool, message: str, k: int, t: float,
                stopped_at: np.ndarray) -> RunResult:
        """The run's result; a successful batch run names its failed members in the message."""
        if success and self._failed.any():
            diverged = all(f is None or f.startswith("diverged") for f in self._failures)
            message += f"; {int(self._failed.sum())} of {self.system.batch} members {'diverged' if diverged else 'failed'}"
        return RunResult(recording, success, message, k, t, stopped_at, self._failed.copy(), list(self._failures))

    # ------------------------------------------------------------------ run
    def run(self) -> RunResult:
        """Initialise every component, step until the stop condition, terminate.

        Returns
        -------
        RunResult
            With ``success = False`` and the recording up to the failure when
            a component fails or the simulation diverges.
        """
        if self.settings.compiled:  # compiled loop (issue 9); None when a component is not covered
            from .compiled import run_compiled

            result = run_compiled(self)
            if result is not None:
                return result
            if f"{__package__}.fmu.component" in sys.modules:  # FMUComponents exist only once it is imported
                from .fmu.master_loop import run_fast_fmu  # all-FMU systems: FastFMULoop (issue 9)

                result = run_fast_fmu(self)
                if result is not None:
                    return result
        s = self.settings
        system = self.system
        comps = system.components
        h = s.step
        n_fine = system.substeps
        schedule = []  # per fine tick: list of (name, h_i)
        for j in range(n_fine):
            tick = []
            for name in self.order:
                every = n_fine // system.rates[name]
                if j % every == 0:
                    tick.append((name, h / system.rates[name]))
            schedule.append(tick)

        max_steps = int(math.floor(s.time_limit / h + 1e-9))
        expected = self.expected_duration or s.time_limit
        capacity = min(max_steps, int(expected / h) + 16) // s.decimation + 2
        probes = []
        for p in self.probes:
            comp, var = split_reference(p.reference)
            probes.append((p.channel, None, var, probe_conversion(system, p), probe_unit(system, p), comp))
        batch = system.batch
        t = s.t0
        k = 0
        success, message = True, ""
        stopped_at = np.full(batch, np.nan)
        self._start()
        recorder = _Recorder(
            [(ch, comps[comp].values, var, f, u) for ch, _, var, f, u, comp in probes], batch, max(capacity, 2)
        )
        recorder.sample(t)
        try:
            report_every = max(1, int(expected / h / 100))
            jacobi = s.method == "jacobi"
            while True:
                flags = self._stop_flags()
                if flags is not None:
                    newly = flags & np.isnan(stopped_at)
                    stopped_at[newly] = t
                    if (flags | self._failed).all():
                        message = self._stop_message(t)
                        break
                if k >= max_steps:
                    success, message = self._time_limit_reached(stopped_at)
                    break
                for j, tick in enumerate(schedule):
                    t_tick = s.t0 + (k * n_fine + j) * (h / n_fine)
                    if jacobi:
                        snap = {id(w): w.source_values[w.source_name].copy() for name, _ in tick for w in self._wires[name]}
                        for name, h_i in tick:
                            self._transfer(self._wires[name], snap)
                        for name, h_i in tick:
                            comps[name].do_step(t_tick, h_i)
                    else:
                        for name, h_i in tick:
                            self._transfer(self._wires[name])
                            comps[name].do_step(t_tick, h_i)
                k += 1
                t = s.t0 + k * h
                for component in self._reporting:
                    if component._pending_failures:  # noqa: SLF001 - cheap check every step
                        self._collect_member_failures()
                        break
                if k % s.check_every == 0:
                    self._check_divergence(t)
                if k % s.decimation == 0:
                    recorder.sample(t)
                if self.progress is not None and k % report_every == 0:
                    self.progress(t - s.t0, expected)
            self._check_divergence(t)
            if (k % s.decimation) != 0:
                recorder.sample(t)
        except CncTwinError as exc:
            success = False
            message = self._run_failed(exc, t)
        finally:
            ended = self._terminate_all()
        success, message = self._terminated(success, message, ended, t)
        return self._result(recorder.recording(success, message, system.name), success, message, k, t, stopped_at)


def simulate_system(
    system: System,
    probes: Sequence[Probe | str] = (),
    settings: MasterSettings | None = None,
    **kwargs: object,
) -> RunResult:
    """Run ``system`` with a :class:`Master` (convenience wrapper).

    Parameters
    ----------
    system : System
        Components and connections.
    probes : sequence of Probe or str
        What to record.
    settings : MasterSettings, optional
        Run settings; keyword arguments are forwarded to :class:`MasterSettings`
        when ``settings`` is None (unknown keywords raise ``TypeError``).
    """
    if settings is None:
        settings = MasterSettings(**kwargs)  # type: ignore[arg-type]
    elif kwargs:
        raise TypeError(f"give either settings or keyword settings, not both: {sorted(kwargs)}")
    return Master(system, settings, probes).run()
