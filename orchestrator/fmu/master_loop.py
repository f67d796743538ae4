"""``run_fast_fmu``: :meth:`Master.run` over FMUs with the step loop of :class:`~.fast_loop.FastFMULoop`.

When every component of the system is an :class:`~.component.FMUComponent`
(FMI 2.0 or FMI 3.0, mixed or not) and the run asks only for what the
compiled loop can do (Real connections; probes and stop signals on Real,
Boolean or Integer outputs; limits on Real outputs; of an FMI 3.0 FMU only
``Float64`` variables), the master hands its step loop to
:class:`FastFMULoop` (issue 9).
The Python side does what the master does around its loop, with the
master's own methods: set-up along the execution order, the stop and
time-limit messages, divergence checks (:meth:`Master._check_divergence` on
the values handed back), progress, recording and termination.

The C loop runs in chunks (at most :data:`CHUNK_STEPS` steps, and up to the
next progress report). Within a chunk it records every probe every step,
and returns early after the first step at which every stop signal is true,
or at a check step (``k % check_every == 0``) at which a connected output or
a limited output is not finite or outside its limits — the same test the
master makes, which then raises the master's own :class:`SimulationError`.
The FMUs therefore never step past the point where the Python master would
have ended: recordings, :class:`~orchestrator.master.RunResult` fields and
the values the components hold afterwards are the Python loop's, bit for bit
(tested). An FMI call that fails ends the run with the master's message and
the recording of the steps completed before it.

Everything else (other component types, discrete connections, probes on
inputs or parameters, FMI 3.0 variables other than ``Float64`` in a
connection, probe, stop signal or limit, no C compiler) runs on the Python
loop; :func:`fast_fmu_support` says why.
"""
from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

import numpy as np

from ..errors import CncTwinError
from ..master import probe_conversion, probe_unit
from ..recording import Recording
from ..system import split_reference
from . import fmi3
from .component import FMUComponent
from .errors import FMUError
from .fast_loop import FastFMULoop, FastLoopResult, compiler

if TYPE_CHECKING:
    from ..master import Master, RunResult

log = logging.getLogger(__name__)

#: Longest chunk of the compiled loop between two returns to Python, steps.
CHUNK_STEPS = 20_000

_RECORDABLE = ("Real", "Boolean", "Integer")


def fast_fmu_support(master: "Master") -> str | None:
    """None when :func:`run_fast_fmu` covers ``master``'s run, else the reason it does not.

    Parameters
    ----------
    master : Master
        A master that has not run yet.
    """
    comps = master.system.components
    others = [f"{n} ({type(c).__name__})" for n, c in comps.items() if not isinstance(c, FMUComponent)]
    if others:
        return f"not every component is an FMUComponent: {', '.join(others)}"
    if sorted(master.order) != sorted(comps):
        return f"the execution order {master.order} does not name every component once: {sorted(comps)}"
    not_new = [n for n, c in comps.items() if c.state != "instantiated"]
    if not_new:
        return f"component(s) {not_new} are not in state 'instantiated'"
    for c in master.system.connections:
        for ref, causality in ((c.source, "output"), (c.target, "input")):
            comp, var = split_reference(ref)
            declared = comps[comp].variable(var)
            if declared.type != "Real" or declared.causality != causality:
                return f"connection {c.source} -> {c.target}: {ref} is a {declared.type} {declared.causality}"
            fmi3_type = _fmi3_type(comps[comp], var)
            if fmi3_type not in (None, "Float64"):
                return (f"connection {c.source} -> {c.target}: {ref} is an FMI 3.0 {fmi3_type} {causality} "
                        "(the FMU loop connects Float64 variables of FMI 3.0 FMUs only)")
    wanted = ([(p.reference, "probe", _RECORDABLE) for p in master.probes]
              + [(r, "stop signal", _RECORDABLE) for r in master.settings.stop_signals()]
              + [(r, "limit", ("Real",)) for r in master.settings.limits])
    for ref, what, types in wanted:
        comp, var = split_reference(ref)
        declared = comps[comp].variable(var)
        if declared.causality != "output" or declared.type not in types:
            return (f"{what} {ref} is a {declared.type} {declared.causality} "
                    f"(the FMU loop takes {'/'.join(types)} outputs)")
        fmi3_type = _fmi3_type(comps[comp], var)
        if fmi3_type not in (None, "Float64"):
            return (f"{what} {ref} is an FMI 3.0 {fmi3_type} output "
                    "(the FMU loop takes Float64 outputs of FMI 3.0 FMUs only)")
    if compiler() is None:
        return "no C compiler (gcc or cc on PATH, or $CC)"
    return None


def run_fast_fmu(master: "Master") -> "RunResult | None":
    """Run ``master`` with :class:`FastFMULoop`; None (nothing done) when its run is not covered.

    Parameters
    ----------
    master : Master
        A master that has not run yet.

    Returns
    -------
    RunResult or None
        The same result :meth:`Master.run` returns from its Python loop (bit-identical
        recording), or None (see :func:`fast_fmu_support`).
    """
    reason = fast_fmu_support(master)
    if reason is not None:
        log.debug("%s: compiled FMU loop not used: %s", master.system.name, reason)
        return None
    s = master.settings
    system = master.system
    comps = system.components
    h = s.step
    max_steps = int(math.floor(s.time_limit / h + 1e-9))
    expected = master.expected_duration or s.time_limit
    report_every = max(1, int(expected / h / 100))
    stop_refs = master._stop_refs  # noqa: SLF001 - the master's own state, as run_compiled
    probes = []  # (channel, column, (factor, offset), unit)
    record: list[str] = []
    for p in master.probes:
        if p.reference not in record:
            record.append(p.reference)
        probes.append((p.channel, record.index(p.reference), probe_conversion(system, p), probe_unit(system, p)))
    checks = {c.source: (-math.inf, math.inf) for c in system.connections}
    for ref, (lo, hi) in s.limits.items():
        checks[ref] = (float(lo), float(hi))
    try:  # before any set-up: a loop that cannot be built (the C compiler fails) leaves the run to Python
        loop = FastFMULoop.from_system(system, record, method=s.method, stop=stop_refs, checks=checks,
                                       check_every=s.check_every)
    except FMUError as exc:
        log.debug("%s: compiled FMU loop not used: %s", system.name, exc)
        return None
    t = s.t0
    k = 0
    success, message = True, ""
    stopped_at = np.full(1, np.nan)
    master._start()  # noqa: SLF001 - failure bookkeeping and component set-up, as Master.run
    steps: list[np.ndarray] = [np.zeros(1, dtype=np.int64)]
    rows: list[np.ndarray] = [np.array([[float(_value(comps, ref)) for ref in record]]).reshape(1, len(record))]

    def keep(result: FastLoopResult, k0: int, first: int, last: int) -> None:
        """Keep the rows of steps ``first .. last`` that the master samples (``k % decimation == 0``).

        ``result`` is the chunk that started at step ``k0`` (its row 0).
        """
        ks = np.arange(first, last + 1)
        take = ks % s.decimation == 0
        steps.append(ks[take])
        rows.append(result.values[first - k0: last - k0 + 1][take])

    def progress(k: int) -> None:
        if master.progress is not None and k % report_every == 0:
            master.progress(s.t0 + k * h - s.t0, expected)

    try:
        flags = master._stop_flags()  # noqa: SLF001
        stopped = flags is not None and bool(flags.all())
        while not stopped and k < max_steps:
            k_limit = min(max_steps, k + CHUNK_STEPS)
            if master.progress is not None:
                k_limit = min(k_limit, (k // report_every + 1) * report_every)
            k0 = k
            try:
                result = loop.run(k_limit - k0, h, s.t0)
            except FMUError:
                partial = loop.partial
                if partial is not None:  # the steps completed before the failing call, as the master
                    k = k0 + partial.values.shape[0] - 1
                    t = s.t0 + k * h
                    keep(partial, k0, k0 + 1, k)
                raise
            k = k0 + result.values.shape[0] - 1
            t = s.t0 + k * h
            if result.event == "check":  # the master's own check at step k (it raises for B = 1), then the sample
                keep(result, k0, k0 + 1, k - 1)
                master._check_divergence(t)  # noqa: SLF001
                keep(result, k0, k, k)
                progress(k)
                flags = master._stop_flags()  # noqa: SLF001 - the loop returned before its stop test
                stopped = flags is not None and bool(flags.all())
                continue
            keep(result, k0, k0 + 1, k)
            progress(k)
            stopped = result.event == "stop"
        if stopped:
            stopped_at[:] = t
            message = master._stop_message(t)  # noqa: SLF001
        else:
            success, message = master._time_limit_reached(stopped_at)  # noqa: SLF001
        master._check_divergence(t)  # noqa: SLF001
        if k % s.decimation != 0:
            steps.append(np.array([k]))
            rows.append(np.array([[float(_value(comps, ref)) for ref in record]]).reshape(1, len(record)))
    except CncTwinError as exc:
        success = False
        message = master._run_failed(exc, t)  # noqa: SLF001
    finally:
        ended = master._terminate_all()  # noqa: SLF001
    success, message = master._terminated(success, message, ended, t)  # noqa: SLF001
    ks = np.concatenate(steps)
    table = np.concatenate(rows, axis=0)
    channels = {"t_s": s.t0 + ks * h}
    units = {"t_s": "s"}
    for channel, column, (factor, offset), unit in probes:
        channels[channel] = table[:, column] * factor
        if offset != 0.0:  # as the master's recorder: factor, then offset
            channels[channel] += offset
        units[channel] = unit
    recording = Recording.from_channels(channels, units, success, message, system.name)
    return master._result(recording, success, message, k, t, stopped_at)  # noqa: SLF001


def _fmi3_type(component: FMUComponent, variable: str) -> str | None:
    """FMI 3.0 type of ``variable`` (our name) of ``component`` (``"Float32"``), None for an FMI 2.0 FMU."""
    if not fmi3.is_fmi3(component.fmi_version):
        return None
    return component._by_name[variable].theirs.type  # noqa: SLF001 - same package


def _value(comps: dict, reference: str) -> float:
    """Current value of ``component.variable`` held by the component (our units; a bool or int as a float)."""
    comp, var = split_reference(reference)
    return comps[comp].values[var][0]
