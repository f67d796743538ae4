"""The systems the benchmark times, besides the twin itself.

* :class:`Lag` / :func:`native_lag_ring`: the C-FMU fixture's model as a
  native (numpy, batched) component, four of them in the same ring: the
  Python master's own overhead per communication step over native components.
* :func:`servo_fmu_system`: the project's own pythonfmu FMUs (MCU and three
  DriveAxis instances, servo loop at 4 ticks per 1 ms), wired as in the twin,
  with a constant position command.
"""
from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np

from fmus_src.component import Component, Variable

from ..machine import AXES, load_machine
from ..system import System
from .cfmu import RING


class Lag(Component):
    """First-order lag ``tau y' = k u - y`` with an exact zero-order-hold step (batched).

    ``y(t + h) = k u + (y(t) - k u) exp(-h / tau)``, ``u`` held over the step;
    the same equations, in the same floating-point order, as the C fixture
    ``orchestrator/bench/lag_fmu/lag.c``.
    """

    variables = (
        Variable("tau", "parameter", "s", 0.01, "time constant"),
        Variable("k", "parameter", "1", 1.0, "static gain"),
        Variable("y0", "parameter", "1", 0.0, "output at t0"),
        Variable("u", "input", "1", 0.0, "input, held over the step"),
        Variable("y", "output", "1", 0.0, "output"),
    )

    def _setup(self, t0: float) -> None:
        self.values["y"][...] = self.values["y0"]

    def _do_step(self, t: float, h: float) -> None:
        v = self.values
        target = v["k"] * v["u"]
        v["y"][...] = target + (v["y"] - target) * np.exp(-h / v["tau"])


def native_lag_ring(batch: int = 1, tau: float = 0.01, k_last: float = 1.0) -> System:
    """Four native :class:`Lag` components in the ring of :func:`~orchestrator.bench.cfmu.lag_ring`."""
    system = System("native_lag_ring")
    for name in RING:
        system.add(Lag(name, batch=batch, tau=tau, k=k_last if name == "d" else 1.0, y0=1.0 if name == "a" else 0.0))
    for src, dst in zip(RING, RING[1:] + RING[:1]):
        system.connect(f"{src}.y", f"{dst}.u")
    system.set_execution_order(RING)
    return system


def _sources_digest() -> str:
    """Digest of every ``fmus_src`` source and the default machine file (what the servo FMUs are built from)."""
    import fmus_src

    from ..machine import MACHINES_DIR

    root = Path(fmus_src.__file__).resolve().parent
    files = sorted(root.rglob("*.py")) + [MACHINES_DIR / "default.toml"]
    digest = hashlib.sha1()
    for f in files:
        digest.update(str(f.relative_to(root.parent) if root.parent in f.parents else f.name).encode())
        digest.update(f.read_bytes())
    return digest.hexdigest()[:12]


def build_servo_fmus(out_dir: str | Path) -> tuple[Path, Path]:
    """Build ``MCU.fmu`` and ``DriveAxis.fmu`` with the default machine's values, in ``out_dir/<digest>/``.

    The sub-folder is named by a digest of the sources, so FMUs built from
    another version of the components are never reused (a pythonfmu FMU runs
    the ``fmus_src`` of the importing process, which must match its model
    description).
    """
    from ..fmu import build_fmus

    out_dir = Path(out_dir) / _sources_digest()
    mcu, drive = out_dir / "MCU.fmu", out_dir / "DriveAxis.fmu"
    if not (mcu.is_file() and drive.is_file()):
        mcu, drive = build_fmus(out_dir, "default", components=["MCU", "DriveAxis"])
    return mcu, drive


def servo_fmu_system(mcu_fmu: str | Path, drive_fmu: str | Path,
                     command_mm: tuple[float, float, float] = (1.0, 0.5, -0.2),
                     velocity_loop_period: float = 250e-6, step: float = 1e-3) -> System:
    """The twin's servo loop over the project's pythonfmu FMUs (batch 1).

    ``mcu.{a}_ref`` is held at ``command_mm`` (a position step from rest at 0);
    ``{a}_drive.position / velocity -> mcu``, ``mcu.{a}_current_cmd -> {a}_drive``.
    MCU and drives run ``step / velocity_loop_period`` times per communication step.
    """
    from ..fmu import FMUComponent
    from ..twin import drive_parameters

    machine = load_machine("default")
    rate = max(1, int(round(step / velocity_loop_period)))
    system = System("servo_fmus")
    mcu = FMUComponent(mcu_fmu, "mcu", parameters={f"{a}_ref": c * 1e-3 for a, c in zip(AXES, command_mm)})
    system.add(mcu, rate=rate)
    for a in AXES:
        system.add(FMUComponent(drive_fmu, f"{a}_drive", parameters=drive_parameters(machine, a)), rate=rate)
    for a in AXES:
        system.connect(f"{a}_drive.position", f"mcu.{a}_position")
        system.connect(f"{a}_drive.velocity", f"mcu.{a}_velocity")
        system.connect(f"mcu.{a}_current_cmd", f"{a}_drive.current_cmd")
    system.set_execution_order(["mcu", *(f"{a}_drive" for a in AXES)])
    return system


def plain_fmpy_loop(system: System, n_steps: int, h: float, t0: float = 0.0,
                    record: tuple[str, ...] = ()) -> np.ndarray:
    """The reference: a plain Python loop over fmpy's ``FMU2Slave`` (``setReal``/``doStep``/``getReal``).

    What a user writes without a co-simulation master: every instance of
    ``system`` (FMUComponents) is set up, then each tick sets all Real inputs
    of a component from a dict of current outputs, steps it and reads all its
    Real outputs back, Gauss–Seidel in the system's execution order, with
    fmpy's convenience methods (which check every status).

    Returns
    -------
    ndarray, shape (n_steps + 1, len(record))
        Recorded outputs (FMU units), row ``k`` at ``t0 + k h``.
    """
    order = system.execution_order()
    comps = system.components
    for name in order:  # set up along the order with connected inputs first, as the master does
        for c in system.connections:
            if c.target_component == name:
                source_value = comps[c.source_component].values[c.source_variable]
                comps[name].values[c.target_variable][...] = source_value * c.factor
        comps[name].setup(t0)
    source = {c.target: (c.source, c.factor) for c in system.connections}
    current: dict[str, float] = {}
    plan = []
    for name in order:
        comp = comps[name]
        slave = comp._slave  # noqa: SLF001 - the fmpy instance behind the component
        ins = [(b.theirs.valueReference, f"{name}.{b.ours.name}") for b in comp._bindings  # noqa: SLF001
               if b.ours.causality == "input" and b.ours.type == "Real"]
        outs = [(b.theirs.valueReference, f"{name}.{b.ours.name}") for b in comp._bindings  # noqa: SLF001
                if b.ours.causality == "output" and b.ours.type == "Real"]
        for vr, ref in ins:
            current[ref] = float(comp.values[ref.split(".", 1)[1]][0])
        for vr, ref in outs:
            current[ref] = float(comp.values[ref.split(".", 1)[1]][0])
        plan.append((name, slave, [vr for vr, _ in ins], [r for _, r in ins],
                     [vr for vr, _ in outs], [r for _, r in outs]))
    n_fine = system.substeps
    schedule = [[(p, h / system.rates[p[0]]) for p in plan if j % (n_fine // system.rates[p[0]]) == 0]
                for j in range(n_fine)]
    rec = np.empty((n_steps + 1, len(record)))
    rec[0] = [current[r] for r in record]
    dt = h / n_fine
    for k in range(n_steps):
        for j, tick in enumerate(schedule):
            t = t0 + (k * n_fine + j) * dt
            for (name, slave, in_vr, in_refs, out_vr, out_refs), h_i in tick:
                if in_vr:
                    slave.setReal(in_vr, [current[source[r][0]] * source[r][1] if r in source else current[r]
                                          for r in in_refs])
                slave.doStep(t, h_i)
                if out_vr:
                    current.update(zip(out_refs, slave.getReal(out_vr)))
        rec[k + 1] = [current[r] for r in record]
    for name in order:
        comps[name].terminate()
    return rec


def ring_exact(n_steps: int, h: float, tau: float = 0.01, k_last: float = 1.0) -> np.ndarray:
    """Exact Gauss–Seidel recursion of the four-lag ring (numpy, float64), shape (n_steps + 1, 4).

    Stage ``i`` steps with the output of stage ``i - 1`` of the *same* tick
    (stage ``a`` with ``d`` of the previous step), ``y <- k u + (y - k u) e``.
    """
    e = math.exp(-h / tau)
    gains = [1.0, 1.0, 1.0, k_last]
    y = np.array([1.0, 0.0, 0.0, 0.0])
    out = np.empty((n_steps + 1, 4))
    out[0] = y
    for k in range(n_steps):
        for i in range(4):
            target = gains[i] * y[i - 1]
            y[i] = target + (y[i] - target) * e
        out[k + 1] = y
    return out
