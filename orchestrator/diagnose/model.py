"""Effect models in spec units, stacked over batch members and simulated with the replay.

A *model* of one axis is ``{effect: {parameter (spec name): value}}``;
mismatch effects (friction, inertia, feed-forward) are differences to the
machine file, the others absolute values, as in ``diagnosis.json``. The
pseudo-effect ``servo_scales`` (``Spp``, ``Svp``, ``Svi``) carries the
identified scale factors so that the refit can move them too.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import numpy as np

from ..identify.start_state import AxisStart
from ..machine import Machine
from ..twin import drive_parameters, mcu_parameters
from .library import component_values
from .replay import run_replay

AxisModel = dict[str, dict[str, float]]
Model = dict[str, AxisModel]

SCALE_KEYS = {"Spp": "position_scale", "Svp": "velocity_p_scale", "Svi": "velocity_i_scale"}


def defaults(machine: Machine, axis: str) -> dict[tuple[str, str], float]:
    """Value of a parameter when a member's model does not mention it (the machine's baseline)."""
    sec = machine.si(f"axis.{axis}")
    out = {("current_saturation", "limit_A"): float(sec["peak_current"])}
    for sym, key in SCALE_KEYS.items():
        out[("servo_scales", sym)] = float(sec[key])
    return out


def stack(models: Sequence[AxisModel], machine: Machine, axis: str) -> dict[str, dict[str, np.ndarray]]:
    """Per-member models of one axis as ``{effect: {parameter: (B,) array}}`` (absent -> baseline)."""
    keys: list[tuple[str, str]] = []
    for m in models:
        for effect, params in m.items():
            for p in params:
                if (effect, p) not in keys:
                    keys.append((effect, p))
    base = defaults(machine, axis)
    out: dict[str, dict[str, np.ndarray]] = {}
    for effect, p in keys:
        arr = np.array([float(m.get(effect, {}).get(p, base.get((effect, p), 0.0))) for m in models])
        out.setdefault(effect, {})[p] = arr
    return out


@dataclass
class Simulated:
    """Simulated channels at the sample times, per axis, shape (n, B).

    Attributes
    ----------
    fe : dict
        Following error ``cmd - table`` [µm].
    current : dict
        Current command [A].
    motor : dict
        Motor-side position [m].
    force : dict
        Motor force [N].
    """

    fe: dict[str, np.ndarray]
    current: dict[str, np.ndarray]
    motor: dict[str, np.ndarray]
    force: dict[str, np.ndarray]


def simulate(machine: Machine, t: np.ndarray, commands: Mapping[str, np.ndarray],
             members: Sequence[Model], t_start: float | None = None,
             twin: Mapping[str, Callable[[np.ndarray, float], np.ndarray]] | None = None,
             disturbance: Mapping[str, Callable[[np.ndarray], np.ndarray]] | None = None,
             start: Mapping[str, AxisStart] | None = None) -> Simulated:
    """Replay all axes of ``commands`` for every member model at once.

    Parameters
    ----------
    machine : Machine
    t : ndarray, shape (n,)
        Sample times (replay clock), s.
    commands : mapping axis -> ndarray, shape (n,)
        Commanded positions [m] at ``t``.
    members : sequence of Model
        One model per batch member.
    t_start : float, optional
        First servo tick on the replay clock (see :func:`run_replay`).
    twin : mapping axis -> callable, optional
        ``twin[a](q, s)``: the twin's command of axis ``a`` [m] at replay-clock times ``q``, taken ``s``
        seconds later on the program clock (:meth:`.prepare.Prepared.twin_commands`), for axes whose
        commands are the twin's, not recorded. The replay samples it at its servo ticks, shifted by a
        member's ``command_shift.shift_ms``. The following error stays relative to ``commands`` (the
        comparison is then on positions).
    disturbance : mapping axis -> callable, optional
        Recorded cutting force on the axis, ``f(t)`` [N] (:func:`.replay.run_replay`).
    start : mapping axis -> AxisStart, optional
        The state the recording implies at its first sample (:attr:`.prepare.Prepared.start`): every member
        starts from it, its integrator holding that member's own force balance (:func:`.replay.run_replay`).
    """
    batch = len(members)
    base_mcu = mcu_parameters(machine)
    mcu_values: dict[str, np.ndarray] = {}
    drive_values: dict[str, dict] = {}
    cmds: dict[str, np.ndarray] = {}
    for a in commands:
        stacked = stack([m.get(a, {}) for m in members], machine, a)
        shift = stacked.pop("command_shift", {}).get("shift_ms")
        source = twin.get(a) if twin else None
        if source is None:
            cmds[a] = np.asarray(commands[a], float)
        elif shift is not None and np.any(shift != 0.0):
            cmds[a] = (lambda q, source=source, shift=shift:
                       np.column_stack([source(q, float(s) * 1e-3) for s in shift]))
        else:
            cmds[a] = (lambda q, source=source: source(q, 0.0))
        scales = stacked.pop("servo_scales", {})
        for sym, arr in scales.items():
            mcu_values[f"{a}_{SCALE_KEYS[sym]}"] = arr
        d, mc = component_values(a, stacked, drive_parameters(machine, a), base_mcu)
        drive_values[a] = {k: np.broadcast_to(np.asarray(v, float), (batch,)).copy() for k, v in d.items()}
        mcu_values.update({k: np.broadcast_to(np.asarray(v, float), (batch,)).copy() for k, v in mc.items()})
    run = run_replay(machine, t, cmds, t, batch=batch, mcu_values=mcu_values, drive_values=drive_values,
                     t_start=t_start, disturbance=disturbance, start=start)
    fe = {a: (np.asarray(commands[a], float)[:, None] - run.table[a]) * 1e6 for a in commands}
    return Simulated(fe, run.current, run.motor, run.force)
