"""Parity: the same scenario with native components and with their pythonfmu FMUs.

The FMUs run the very same Python code in the same process; the FMI layer
only moves IEEE doubles (and ints/bools/strings) through ctypes, which is
exact. Expected: identical recordings (asserted: max difference <= 1e-9
relative to the channel's range; measured 0).
"""
from __future__ import annotations

import numpy as np
import pytest

from fmus_src.servo.drive import DriveAxis
from orchestrator import Master, MasterSettings, System
from orchestrator.fmu import FMUComponent, available_components, build_fmus
from orchestrator.twin import DEFAULT_DRIVE_INTEGRATOR

RTOL = 1e-9


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    names = available_components()
    return dict(zip(names, build_fmus(tmp_path_factory.mktemp("fmus"), components=names)))


def _assert_same(a: np.ndarray, b: np.ndarray, what: str) -> None:
    scale = max(np.abs(a).max(), np.abs(b).max(), 1e-300)
    assert np.abs(a - b).max() <= RTOL * scale, what


def test_drive_alone_native_vs_fmu_is_identical(fmus):
    h, n = 250e-6, 1200
    fmu = FMUComponent(fmus["DriveAxis"], name="x_drive", parameters={"initial_position": -0.02})
    nat = DriveAxis("x_drive", initial_position=-0.02, integrator=DEFAULT_DRIVE_INTEGRATOR)  # as the FMU's start
    fmu.setup(0.0)
    nat.setup(0.0)
    outputs = nat.names("output")
    rec = {k: np.zeros((n + 1, 2)) for k in outputs}
    for k in range(n):
        t = k * h
        for c in (fmu, nat):
            c.values["current_cmd"][0] = 8.0 * np.sin(2 * np.pi * 3.0 * t)
            c.values["disturbance_force"][0] = 150.0 * np.cos(2 * np.pi * 7.0 * t)
            c.do_step(t, h)
        for q in outputs:
            rec[q][k + 1] = fmu.values[q][0], nat.values[q][0]
    for q in outputs:
        _assert_same(rec[q][:, 0], rec[q][:, 1], q)
    assert np.abs(rec["position"][:, 1] + 0.02).max() > 1e-3  # it did move
    fmu.close()


def test_population_of_fmu_instances_equals_one_batched_native_component(fmus):
    masses = np.array([400.0, 600.0, 900.0])
    nat = DriveAxis("x_drive", batch=3, mass=masses, integrator=DEFAULT_DRIVE_INTEGRATOR)
    members = [FMUComponent(fmus["DriveAxis"], name=f"x_drive_{i}", parameters={"mass": m})
               for i, m in enumerate(masses)]
    nat.setup(0.0)
    for c in members:
        c.setup(0.0)
    h = 1e-3
    for k in range(200):
        nat.values["current_cmd"][...] = 6.0
        for c in members:
            c.values["current_cmd"][0] = 6.0
            c.do_step(k * h, h)
        nat.do_step(k * h, h)
    got = np.array([c.values["position"][0] for c in members])
    _assert_same(got, nat.values["position"], "position")
    assert got[0] > got[1] > got[2]  # lighter tables go further
    for c in members:
        c.close()


CASE = """program = "part.nc"
[stock]
min = [0.0, 0.0, -10.0]
max = [30.0, 20.0, 0.0]
[tool]
diameter_mm = 6.0
flutes = 2
[machine]
parameters = "default"
"""
PROGRAM = """%
O0003
G21 G17 G90 G94 G54
S2000 M3
G0 X-4. Y10. Z1.
G1 Z-1. F600
X4. F1200
G0 Z5.
M30
%
"""


def _fmu_system(twin, fmus) -> System:
    """The twin's system with every component replaced by an FMU instance with the same parameters."""
    kinds = {"nck": "NCKernel", "mcu": "MCU", "cutting": "CuttingLoad"}
    native = twin.system
    system = System(native.name + "_fmu")
    for name, comp in native.components.items():
        kind = kinds.get(name, "DriveAxis")
        params = {k: (v if isinstance(v, str) else v[0]) for k, v in comp.parameter_values().items()}
        system.add(FMUComponent(fmus[kind], name=name, parameters=params), rate=native.rates[name])
    for c in native.connections:
        system.connect(c.source, c.target)
    system.set_execution_order(native.execution_order())
    return system


def test_full_twin_native_vs_all_fmu_is_identical(fmus, tmp_path):
    assert set(fmus) == {"NCKernel", "MCU", "DriveAxis", "CuttingLoad"}
    from orchestrator.case import load_case
    from orchestrator.twin import build_twin

    (tmp_path / "case.toml").write_text(CASE)
    (tmp_path / "part.nc").write_text(PROGRAM)
    twin = build_twin(load_case(tmp_path))
    assert twin.cutting is not None
    settings = MasterSettings(step=twin.options.step, time_limit=5.0, stop_when=twin.stop_when)
    native = Master(twin.system, settings, twin.probes).run()
    twin2 = build_twin(load_case(tmp_path))
    fmu_system = _fmu_system(twin2, fmus)
    assert all(isinstance(c, FMUComponent) for c in fmu_system.components.values())
    fmu = Master(fmu_system, settings, twin2.probes).run()
    assert native.success, native.message
    assert fmu.success, fmu.message
    assert native.steps == fmu.steps
    assert np.max(native.recording["fc_N"]) > 10.0  # it really cut
    for channel in native.recording.channels:
        _assert_same(fmu.recording[channel], native.recording[channel], channel)
