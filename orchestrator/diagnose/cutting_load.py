"""The cutting load of the feed drives from the diagnosed cutting model (forces sampled too coarsely to carry).

A dynamometer that samples fewer than ``prepare.MIN_FORCE_SAMPLES_PER_TOOTH`` times per tooth period (a
2-flute tool at 6000 rpm logged every 1 ms: 5 samples) cannot be interpolated into the force the drives
carried. Before, the drives then carried the twin's own predicted load (its cutting component's 1 ms step
means at the twin's spindle angle, ``prepare.corrected_forces``), corrected by the recorded-minus-predicted
force averaged over two spindle revolutions. The machine's drives carry the *instantaneous* force at the
*machine's* spindle angle: the twin's tooth pattern was another force (a 1 ms mean halves the 3rd tooth
harmonic and the spindle phase is arbitrary). On the part of :mod:`.scorecard_part` logged every 1 ms that
left up to 0.045 A rms of x current residual while cutting (noise 0.02 A), and a clean recording was named an
x ``velocity_feedforward`` of -0.03.

Here the drives may carry the force of the *diagnosed* cutting model instead (``core._best_load`` takes
whichever load fits the recorded currents best): the refitted coefficients, effects and spindle angle
(:mod:`.cutting_core`), replayed along the recorded tool path on a grid :data:`SUBSTEPS_PER_TICK` times
finer than the velocity loop and averaged over each velocity tick, as the machine's drive integrates the
force over its tick (or over the twin's communication steps, as the twin's drives carry their load). What
the model leaves (an effect the sampling cannot
resolve, a dynamometer offset) is added as before: the recorded-minus-model force averaged over whole
spindle revolutions.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from .cutting_core import CuttingResult
from .cutting_replay import ForceInputs, run_force_replay
from .cutting_library import component_values
from .prepare import CORRECTION_REVOLUTIONS, SampledForce, TwinLoads, _carried_step_mean

#: Force-model samples per velocity-loop tick.
SUBSTEPS_PER_TICK = 4
#: Model parts that are not the force on the workpiece (refitted elsewhere or not replayable sample by sample).
NOT_REPLAYED = ("spindle_droop", "chatter", "alignment")


def fine_inputs(inputs: ForceInputs, step_omega: np.ndarray, substeps: int) -> tuple[ForceInputs, np.ndarray]:
    """The replay inputs on a grid ``substeps`` times finer than the force samples.

    Parameters
    ----------
    inputs : ForceInputs
        At the force samples (tool path linear between them: its curvature over 1 ms is far below the
        chip's micrometres).
    step_omega : ndarray, shape (n - 1,)
        Spindle speed of each step, rad/s (the cuts' phases included): every substep of a step takes it,
        so the spindle angle at each force sample is the one the cutting diagnosis aligned.
    substeps : int
        Substeps per force-sample interval (>= 1).

    Returns
    -------
    (ForceInputs, ndarray)
        The fine inputs and their step speeds.
    """
    t = inputs.t
    m = max(1, int(substeps))
    frac = np.arange(m) / m
    fine_t = np.append((t[:-1, None] + np.diff(t)[:, None] * frac[None, :]).ravel(), t[-1])
    pos = np.column_stack([np.interp(fine_t, t, inputs.position[:, i]) for i in range(3)])
    omega = np.interp(fine_t, t, inputs.omega)
    return ForceInputs(fine_t, pos, omega, inputs.omega_source), np.repeat(np.asarray(step_omega, float), m)


def model_loads(cres: CuttingResult, measured: dict[str, SampledForce], tick_s: float,
                revolution_s: float, steps: TwinLoads | None = None,
                offset: Callable[[], float] = lambda: 0.0) -> dict[str, Callable[[np.ndarray], np.ndarray]]:
    """``{axis: f(q)}``: the force [N] on the x and y drives at logger times ``q``, from the diagnosed cutting model.

    Parameters
    ----------
    cres : CuttingResult
        The cutting half of the diagnosis (its data, refitted model and spindle angle).
    measured : dict axis -> SampledForce
        The recorded forces (for the slow correction).
    tick_s : float
        Velocity-loop period, s: the load of a tick is the model force averaged over it (``q`` its middle).
    revolution_s : float
        Spindle revolution, s (the correction's averaging window is :data:`CORRECTION_REVOLUTIONS` of them).
    steps : TwinLoads, optional
        Carry the model force as the twin's drives carry its own: its mean over each of the twin's
        communication steps (``steps.t0 + k steps.h``, program clock), the first ``steps.stale`` ticks of a
        step still on the previous step's mean (:func:`.prepare._carried_step_mean`). Default: the mean over
        each velocity tick.
    offset : callable
        ``offset()`` -> logger clock minus program clock, s (read at every call), for ``steps``.
    """
    data = cres.data
    t = data.inputs.t
    interval = float(np.median(np.diff(t)))
    substeps = int(math.ceil(interval * SUBSTEPS_PER_TICK / tick_s - 1e-9))
    inputs, step_omega = fine_inputs(data.inputs, data.step_omega, substeps)
    model = {e: v for e, v in cres.model.items() if e not in NOT_REPLAYED}
    params = {"kt": data.kt, "ke": data.ke, **component_values(model)}
    theta = data.theta0 + math.radians(cres.model.get("alignment", {}).get("spindle_phase_deg", 0.0))
    rep = run_force_replay(data.case, data.table, inputs, [params], theta, step_omega)
    fine = {"x": rep.fx[:, 0], "y": rep.fy[:, 0]}
    out = {}
    for a, f in fine.items():
        # running integral of the fine force: a tick's mean is a difference of two interpolations
        integral = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(inputs.t))])
        at_samples = f[::substeps]
        slow = np.zeros(t.size)
        if a in measured:
            force = measured[a]
            diff = np.interp(t, force.t, force.f) - at_samples
            window = max(1, int(round(CORRECTION_REVOLUTIONS * revolution_s / interval)))
            slow = np.convolve(diff, np.ones(window) / window, mode="same")

        if steps is not None and a in steps.rate:
            def load(q, ft=inputs.t, integral=integral, slow=slow, a=a):
                q = np.asarray(q, float)
                off = offset()
                n = int(np.ceil((ft[-1] - off - steps.t0) / steps.h)) + 2
                edges = steps.t0 + steps.h * np.arange(-1, n)
                mean = np.diff(np.interp(edges + off, ft, integral)) / steps.h
                return (_carried_step_mean(q - off, steps.t0, steps.h, steps.rate[a], steps.stale[a], mean)
                        + np.interp(q, t, slow, left=0.0, right=0.0))
        else:
            def load(q, ft=inputs.t, integral=integral, slow=slow):
                q = np.asarray(q, float)
                lo = np.interp(q - 0.5 * tick_s, ft, integral)
                hi = np.interp(q + 0.5 * tick_s, ft, integral)
                return (hi - lo) / tick_s + np.interp(q, t, slow, left=0.0, right=0.0)

        out[a] = load
    return out
