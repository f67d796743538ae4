"""Minimal closed-loop harness for the servo tests: one MCU + three DriveAxis, Jacobi stepping.

At every communication point ``t_k = t0 + k h`` the drive outputs (position,
velocity at ``t_k``) are copied to the MCU inputs, the MCU output (the command
of its previous step) to the drives, then every component does ``do_step(t_k, h)``
from those values (a Jacobi master, one velocity-loop tick of computation delay).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from fmus_src.servo import MCU, DriveAxis, drive_parameters, mcu_parameters
from orchestrator.machine import load_machine

AXES = ("x", "y", "z")
TV = 250e-6

#: Friction-free drive parameters (Stribeck velocity must stay > 0).
NO_FRICTION = {
    f"{k}_{d}": (1.0 if k == "stribeck_velocity" else 0.0)
    for k in ("coulomb", "static", "stribeck_velocity", "viscous") for d in ("positive", "negative")
}


def machine_parameters(machine_name: str = "default") -> tuple[dict[str, float], dict[str, dict[str, float]]]:
    """(MCU parameters, {axis: DriveAxis parameters}) of a machine file."""
    m = load_machine(machine_name)
    mcu = mcu_parameters({a: m.si(f"axis.{a}") for a in AXES}, m.si("servo"))
    drives = {
        a: drive_parameters(m.si(f"axis.{a}"), m.si(f"axis.{a}.friction.positive"), m.si(f"axis.{a}.friction.negative"))
        for a in AXES
    }
    return mcu, drives


@dataclass
class Traces:
    """Recorded signals at t_k, k = 0..n: arrays of shape (n + 1, 3, B)."""

    t: np.ndarray
    ref: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    current: np.ndarray
    friction: np.ndarray

    @property
    def following_error(self) -> np.ndarray:
        """ref - position [m], shape (n + 1, 3, B)."""
        return self.ref - self.position


def build(batch: int = 1, friction: bool = True, mcu_overrides: dict | None = None,
          drive_overrides: dict | None = None) -> tuple[MCU, dict[str, DriveAxis]]:
    """Instantiate (not set up) the MCU and the three drives of the default machine."""
    mcu_p, drive_p = machine_parameters()
    mcu_p.update(mcu_overrides or {})
    drives = {}
    for a in AXES:
        p = dict(drive_p[a])
        if not friction:
            p.update(NO_FRICTION)
        p.update((drive_overrides or {}).get(a, {}))
        drives[a] = DriveAxis(f"{a}_drive", batch=batch, **p)
    return MCU("mcu", batch=batch, **mcu_p), drives


def run(mcu: MCU, drives: dict[str, DriveAxis], ref: Callable[[float], np.ndarray], n_steps: int,
        h: float = TV, t0: float = 0.0, disturbance: Callable[[float], np.ndarray] | None = None) -> Traces:
    """Run the closed loop for ``n_steps`` steps of ``h``.

    Parameters
    ----------
    ref : callable
        ``ref(t)`` -> reference positions, array broadcastable to (3, B) [m].
    disturbance : callable, optional
        ``disturbance(t)`` -> Fd, broadcastable to (3, B) [N].
    """
    batch = mcu.batch
    for i, a in enumerate(AXES):
        mcu.set(f"{a}_ref", np.broadcast_to(ref(t0), (3, batch))[i])
    mcu.setup(t0)
    for d in drives.values():
        d.setup(t0)
    shape = (n_steps + 1, 3, batch)
    out = {k: np.zeros(shape) for k in ("ref", "position", "velocity", "current", "friction")}
    times = t0 + h * np.arange(n_steps + 1)
    for k in range(n_steps + 1):
        t = times[k]
        r = np.broadcast_to(ref(t), (3, batch))
        fd = None if disturbance is None else np.broadcast_to(disturbance(t), (3, batch))
        for i, a in enumerate(AXES):
            d = drives[a]
            pos, vel = d.values["position"], d.values["velocity"]
            out["ref"][k, i] = r[i]
            out["position"][k, i] = pos
            out["velocity"][k, i] = vel
            out["friction"][k, i] = d.values["friction_force"]
            cmd = mcu.values[f"{a}_current_cmd"]
            out["current"][k, i] = cmd
            if k == n_steps:
                continue
            mcu.set(f"{a}_ref", r[i])
            mcu.set(f"{a}_position", pos)
            mcu.set(f"{a}_velocity", vel)
            d.set("current_cmd", cmd)
            if fd is not None:
                d.set("disturbance_force", fd[i])
        if k == n_steps:
            break
        mcu.do_step(t, h)
        for a in AXES:
            drives[a].do_step(t, h)
    return Traces(times, out["ref"], out["position"], out["velocity"], out["current"], out["friction"])


def time_per_simulated_second(batch: int, compiled: bool, duration: float = 1.0, h: float = TV,
                              amplitude: float = 0.005, period: float = 0.5) -> float:
    """Wall time [s] of MCU + 3 DriveAxis ``do_step`` calls per simulated second (benchmark, no assert).

    The reference is a sinusoid of ``amplitude`` [m] and ``period`` [s] on all axes (reversals with
    stiction twice per period; 63 mm/s peak at the defaults), members phase-shifted. Only the
    ``do_step`` calls are timed (the Jacobi copies of the harness are not servo time). The first
    step is excluded (it triggers compilation or cache loading).
    """
    import time

    mcu, drives = build(batch=batch)
    saved = MCU.use_compiled, DriveAxis.use_compiled
    mcu.use_compiled = compiled
    for d in drives.values():
        d.use_compiled = compiled
    mcu.setup(0.0)
    for d in drives.values():
        d.setup(0.0)
    phase = np.linspace(0.0, 1.0, batch, endpoint=False)
    n = int(round(duration / h))
    spent = 0.0
    order = [mcu, *drives.values()]
    for k in range(n + 1):
        t = k * h
        r = amplitude * np.sin(2.0 * np.pi * (t / period + phase))
        for a in AXES:
            d = drives[a]
            mcu.values[f"{a}_ref"][...] = r
            mcu.values[f"{a}_position"][...] = d.values["position"]
            mcu.values[f"{a}_velocity"][...] = d.values["velocity"]
            d.values["current_cmd"][...] = mcu.values[f"{a}_current_cmd"]
        start = time.perf_counter()
        for c in order:
            c.do_step(t, h)
        if k > 0:
            spent += time.perf_counter() - start
    assert (MCU.use_compiled, DriveAxis.use_compiled) == saved
    return spent / (n * h)
