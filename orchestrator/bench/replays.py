"""Bench of the servo replay that identification and diagnosis run: compiled against tick by tick.

:func:`time_servo_replay` replays the MCU and drives of the three axes on
the bench part's commanded positions (the twin's own NC run), with ``B``
parameter sets as the diagnosis's effect library has them (every drive
effect term on in some member), through
:func:`orchestrator.diagnose.replay.run_replay` — once on the compiled path
and once forced onto the components' tick-by-tick loop.
"""
from __future__ import annotations

import time

import numpy as np

from fmus_src.servo.replay import stepped_tick_by_tick

from ..case import Case
from ..diagnose.prepare import twin_commands
from ..diagnose.replay import run_replay


def _effect_members(batch: int) -> tuple[dict, dict]:
    """MCU and drive overrides of ``batch`` members, each with a few effect terms on (seeded)."""
    rng = np.random.default_rng(0)
    drives = {"x": {"gravity_force": rng.uniform(0, 50, batch), "reversal_friction_peak": rng.uniform(0, 80, batch),
                    "reversal_friction_decay": np.full(batch, 2e-4)},
              "y": {"backlash_width": rng.uniform(0, 3e-6, batch), "screw_stiffness": np.full(batch, 2e8),
                    "pitch_amplitude": np.full(batch, 1e-6), "pitch_period": np.full(batch, 0.012)},
              "z": {"gravity_force": np.full(batch, 300.0), "ripple_amplitude": rng.uniform(0, 20, batch),
                    "ripple_period": np.full(batch, 0.004)}}
    mcu = {"x_servo_delay": rng.uniform(0, 1e-3, batch), "y_velocity_feedforward": rng.uniform(0, 0.3, batch)}
    return mcu, drives


def time_servo_replay(case: Case, seconds: float, batch: int, compiled: bool = True) -> dict:
    """Wall time of one batched servo replay of the first ``seconds`` of the case's program.

    Parameters
    ----------
    case : Case
        The program and machine (its commands come from the twin's NC run).
    seconds : float
        Replayed duration, s.
    batch : int
        Parameter sets ``B``.
    compiled : bool
        The compiled replay (True) or the components stepped tick by tick (False).

    Returns
    -------
    dict
        ``batch``, ``sim_s``, ``wall_s``, ``rt_factor`` (aggregate: ``B sim_s / wall_s``),
        ``us_per_member_tick`` and ``compiled``.
    """
    nc = twin_commands(case, case.machine)
    t = np.asarray(nc.t, dtype=float)
    t = t[t <= t[0] + seconds]
    cmds = {a: np.asarray(nc[f"{a}_ref_mm"], dtype=float)[: t.size] * 1e-3 for a in "xyz"}
    mcu, drives = _effect_members(batch)
    tv = float(case.machine.si("servo")["velocity_loop_period"])

    def run() -> float:
        start = time.perf_counter()
        run_replay(case.machine, t, cmds, t, batch=batch, mcu_values=mcu, drive_values=drives)
        return time.perf_counter() - start

    if compiled:
        wall = run()
    else:
        with stepped_tick_by_tick():
            wall = run()
    sim = float(t[-1] - t[0])
    ticks = sim / tv
    return {"batch": batch, "sim_s": sim, "wall_s": wall, "rt_factor": batch * sim / wall if wall > 0 else np.inf,
            "us_per_member_tick": wall / (batch * ticks) * 1e6, "compiled": compiled}
