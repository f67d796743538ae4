"""The default twin: NC kernel → MCU → three drive axes (+ cutting load), with feedback.

:func:`build_twin` maps a machine parameter set and a case onto the native
components and wires them by variable name::

    nck.{a}_ref ──► mcu.{a}_ref          mcu.{a}_current_cmd ──► {a}_drive.current_cmd
    {a}_drive.position ──► mcu.{a}_position, cutting.{a}_position
    {a}_drive.velocity ──► mcu.{a}_velocity
    nck.spindle_speed ──► cutting.spindle_speed   (spindle_rpm is recorded from cutting.spindle_speed_actual)
    nck.tool ──► cutting.tool                     (with a tool table, [tools] of case.toml: each tool's cutter)
    cutting.fx_mean / fy_mean ──► x_drive / y_drive.disturbance_force   (Fd = +F on the workpiece)
    cutting.fz ──► z_drive.disturbance_force   (the end edges' thrust, a step mean; Fd = +fz, see below)

Sign of the thrust on Z: ``fz`` (<= 0) is the force on the workpiece; the Z slide carries the tool and feels
the reaction ``-fz`` (>= 0, upward, towards positive z). The drive's ``Fd`` resists positive motion
(``Ms x'' = u - Ff - Fd``), so ``Fd = -(-fz) = fz``: a plunge (z decreasing) needs a motor force
``u = Ff + fz``, more downward by the thrust. (On X and Y the table carries the workpiece and the axis
position is the tool's relative to it, so ``Fd = +F on the workpiece`` there too.)

The servo loop (MCU and drives) runs at the velocity-loop period inside the
1 ms communication step (rate 4 by default); the NC kernel and the cutting
load step at the communication step and substep internally.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, Mapping

import numpy as np

from fmus_src.cutting.component import CuttingLoad
from fmus_src.cutting.path_component import PathCuttingLoad
from fmus_src.cutting.table import EngagementTable
from fmus_src.nck.blocks import ToolChange
from fmus_src.nck.component import NCKernel
from fmus_src.nck.m_aliases import format_m_codes
from fmus_src.servo.drive import DriveAxis
from fmus_src.servo.mcu import MCU

from .case import Case, CaseError, unlisted_tool_error
from .errors import CncTwinError, SystemDescriptionError
from .machine import AXES, Machine, frame_parameters
from .master import Probe
from .memo import digest, remember
from .system import System

#: Default start position of the tool tip in work coordinates, mm (safe height above work zero).
DEFAULT_START_MM = (0.0, 0.0, 50.0)


@dataclass(frozen=True)
class TwinOptions:
    """How the twin is assembled.

    Attributes
    ----------
    step : float
        Communication step, s.
    start_mm : tuple of 3 floats
        Tool-tip start position, mm.
    cutting : bool
        Include the cutting-load component when the case has a stock.
    cutting_mode : {"zmap", "path"}
        ``"zmap"``: every batch member removes material from its own Z-map
        stock (exact for any path). ``"path"``: the engagement along the
        program's reference path is computed once (:func:`engagement_table`)
        and every member reads it — for populations that differ only in F and
        S (the optimiser); members must stay within 0.5 mm of that path.
    engagement : EngagementTable, optional
        A precomputed table for ``cutting_mode="path"`` (reuse it across calls).
    drive_integrator : {"exponential", "rk4"}
        ``DriveAxis.integrator`` of the three drives: one exponential substep per
        velocity-loop tick with RK4 near stick (default; within 1e-10 m of RK4 on the
        bench part, see :mod:`fmus_src.servo.exponential_numba`), or the RK4 reference.
    """

    step: float = 1e-3
    start_mm: tuple[float, float, float] = DEFAULT_START_MM
    cutting: bool = True
    cutting_mode: Literal["zmap", "path"] = "zmap"
    engagement: EngagementTable | None = field(default=None, compare=False, repr=False)
    drive_integrator: Literal["exponential", "rk4"] = "exponential"  # = DEFAULT_DRIVE_INTEGRATOR


def _declared(component_cls: type, mapping: Mapping[str, object]) -> dict[str, object]:
    """The entries of ``mapping`` that ``component_cls`` declares as parameters."""
    names = {v.name for v in component_cls.variables if v.causality == "parameter"}
    return {k: v for k, v in mapping.items() if k in names}


def nck_parameters(machine: Machine) -> dict[str, object]:
    """NC kernel parameters (SI) from a machine file.

    A 2nd/3rd/4th reference position (G30) the file leaves out is its 1st one (``reference_*_mm``). The M-code
    aliases of ``[nck.m_codes]`` become the String parameter ``m_codes`` (none in the file: no aliases). The stroke
    limits of ``[axis.<a>]`` switch on the stored stroke check of that axis (:func:`stroke_parameters`). A file
    with ``machine_zero_*_mm`` also sets the default work offsets G54..G59 to -machine zero
    (:func:`~orchestrator.machine.frame_parameters`).
    The in-position check before a rapid that follows cutting feed (``[nck] in_position_before_rapid``, "on" when
    left out) models the servo with each axis's ``position_gain_per_s`` x ``position_scale``.
    """
    params: dict[str, object] = dict(machine.si("nck"))
    params.update(frame_parameters(machine))
    for n in (2, 3, 4):
        for a in AXES:
            if f"reference_{a}" in params:
                params.setdefault(f"reference{n}_{a}", params[f"reference_{a}"])
    params.update({f"spindle_{k}": v for k, v in machine.si("spindle").items()})
    for a in AXES:
        axis = machine.si(f"axis.{a}")
        params[f"{a}_rapid_feed"] = axis["rapid_feed"]
        params[f"{a}_position_gain"] = float(axis["position_gain"]) * float(axis["position_scale"])
    # [nck] in_position_before_rapid: "on" or "off"; left out, the kernel's default (on, FANUC's behaviour) applies
    if "in_position_before_rapid" in params:
        params["in_position_before_rapid"] = params["in_position_before_rapid"] == "on"
    params["m_codes"] = format_m_codes(machine.m_codes())  # [nck.m_codes]; none in the file: no aliases
    params.update(stroke_parameters(machine))
    return _declared(NCKernel, params)


def stroke_parameters(machine: Machine) -> dict[str, object]:
    """The NC kernel's stored stroke check parameters from ``[axis.<a>] stroke_min_mm/stroke_max_mm`` (SI).

    An axis without limits in the file keeps ``<a>_stroke_check`` off (not checked).
    """
    params: dict[str, object] = {}
    for a, (lo, hi) in machine.stroke_limits().items():
        params.update({f"{a}_stroke_check": True, f"{a}_stroke_min": lo, f"{a}_stroke_max": hi})
    return params


def mcu_parameters(machine: Machine) -> dict[str, object]:
    """MCU parameters (SI) from a machine file."""
    params: dict[str, object] = dict(machine.si("servo"))
    params["in_position_width"] = machine.si("nck")["in_position_width"]
    for a in AXES:
        params.update({f"{a}_{k}": v for k, v in machine.si(f"axis.{a}").items()})
        params.update({f"{a}_{k}": v for k, v in _effects(machine, a).items()})
    return _declared(MCU, params)


def _effects(machine: Machine, axis: str) -> dict[str, float | str]:
    """The optional ``[axis.<a>.effects]`` section in SI (empty for the paper's baseline)."""
    section = f"axis.{axis}.effects"
    return machine.si(section) if machine.has_section(section) else {}


#: ``DriveAxis.integrator`` of the twin's drives (and of the servo replays, which are the twin's loop).
DEFAULT_DRIVE_INTEGRATOR = "exponential"


def drive_parameters(machine: Machine, axis: str) -> dict[str, object]:
    """Drive-axis parameters (SI) of one axis from a machine file (integrator: :data:`DEFAULT_DRIVE_INTEGRATOR`)."""
    params: dict[str, object] = dict(machine.si(f"axis.{axis}"))
    for direction in ("positive", "negative"):
        params.update({f"{k}_{direction}": v for k, v in machine.si(f"axis.{axis}.friction.{direction}").items()})
    params.update(_effects(machine, axis))
    params["integrator"] = DEFAULT_DRIVE_INTEGRATOR
    return _declared(DriveAxis, params)


#: ``[cutting.effects]`` key (unit suffix stripped by ``Machine.si``) -> CuttingLoad parameter.
CUTTING_EFFECT_PARAMETERS: dict[str, str] = {
    "eccentricity": "runout_eccentricity", "phase": "runout_phase", "helix": "helix_angle",
    "kte": "edge_force_tangential", "kre": "edge_force_radial", "tool_stiffness": "tool_stiffness",
    "wear_rate": "wear_rate", "spindle_droop": "spindle_droop", "chatter_frequency": "chatter_frequency",
    "chatter_damping_ratio": "chatter_damping", "chatter_stiffness": "chatter_stiffness",
}


def cutting_effect_parameters(machine: Machine) -> dict[str, float]:
    """The optional ``[cutting.effects]`` section as CuttingLoad parameters (SI; empty for the paper's baseline)."""
    if not machine.has_section("cutting.effects"):
        return {}
    return {CUTTING_EFFECT_PARAMETERS[k]: float(v) for k, v in machine.si("cutting.effects").items()}


def cutting_parameters(case: Case) -> dict[str, object]:
    """Cutting-load parameters (SI) from a case (tool, tool table, stock, material, ``[cutting.effects]``)."""
    params: dict[str, object] = {
        "tool_diameter": case.tool.diameter_mm * 1e-3,
        "flutes": case.tool.flutes,
    }
    for i, (number, tool) in enumerate(case.tools.items(), start=1):  # the tool table, [tools.T<n>]
        params.update({f"tool_{i}_number": number, f"tool_{i}_diameter": tool.diameter_mm * 1e-3,
                       f"tool_{i}_flutes": tool.flutes})
    if case.material:
        params.update(case.machine.si(f"material.{case.material}"))
    params.update(cutting_effect_parameters(case.machine))
    if case.stock is not None:
        for i, a in enumerate(AXES):
            params[f"stock_{a}_min"] = case.stock.min_mm[i] * 1e-3
            params[f"stock_{a}_max"] = case.stock.max_mm[i] * 1e-3
    return _declared(CuttingLoad, params)


def _check_tools_listed(case: Case, nck: NCKernel) -> None:
    """With a tool table and no ``[tool]``, every M6 of the program changes to a listed tool (else
    :class:`~orchestrator.case.CaseError` naming the program line and the case file)."""
    if case.tool_stated:
        return
    nck.planning_inputs()  # interprets the program (set-up does it again, with the plan)
    changes = [(b.line, b.tool) for b in nck.program_.blocks if isinstance(b, ToolChange)]
    why = unlisted_tool_error(case, changes)
    if why is not None:
        raise CaseError(why)


@dataclass
class Twin:
    """An assembled twin: the system, its components and what to record."""

    system: System
    nck: NCKernel
    mcu: MCU
    drives: dict[str, DriveAxis]
    cutting: CuttingLoad | None
    probes: list[Probe]
    options: TwinOptions
    stop_when: tuple[str, ...] = ("nck.done",)
    limits: dict[str, tuple[float, float]] | None = None


def build_twin(
    case: Case,
    batch: int = 1,
    options: TwinOptions | None = None,
    program_text: str | None = None,
) -> Twin:
    """Assemble the default twin for a case.

    Parameters
    ----------
    case : Case
        Program, stock, tool, machine.
    batch : int
        Batch size ``B`` of every component.
    options : TwinOptions, optional
        Step, start position, whether to cut.
    program_text : str, optional
        G-code text to run instead of reading ``case.program``.

    Returns
    -------
    Twin
    """
    options = options or TwinOptions()
    machine = case.machine
    start = np.asarray(options.start_mm, dtype=float) * 1e-3
    servo = machine.si("servo")
    rate = max(1, int(round(options.step / float(servo["velocity_loop_period"]))))

    nck_params = nck_parameters(machine)
    nck_params.update(case.offsets.nck_parameters())  # [offsets] of case.toml: D and H registers
    nck_params.update({f"{a}_initial": start[i] for i, a in enumerate(AXES)})
    nck = NCKernel("nck", batch=batch, program_file=str(case.program), **nck_params)
    if program_text is not None:
        nck.set_program_text(program_text, str(case.program))
    mcu = MCU("mcu", batch=batch, **mcu_parameters(machine))
    drives = {
        a: DriveAxis(f"{a}_drive", batch=batch, initial_position=start[i],
                     **{**drive_parameters(machine, a), "integrator": options.drive_integrator})
        for i, a in enumerate(AXES)
    }
    system = System("cnctwin")
    system.add(nck, rate=1)
    system.add(mcu, rate=rate)
    for drive in drives.values():
        system.add(drive, rate=rate)
    for a in AXES:
        system.connect(f"nck.{a}_ref", f"mcu.{a}_ref")
        system.connect(f"{a}_drive.position", f"mcu.{a}_position")
        system.connect(f"{a}_drive.velocity", f"mcu.{a}_velocity")
        system.connect(f"mcu.{a}_current_cmd", f"{a}_drive.current_cmd")

    cutting = None
    if options.cutting and case.stock is not None:
        if options.cutting_mode == "path":
            cutting = PathCuttingLoad("cutting", batch=batch, **cutting_parameters(case))
            cutting.attach_table(options.engagement or engagement_table(case, options, program_text))
        elif options.cutting_mode == "zmap":
            cutting = CuttingLoad("cutting", batch=batch, **cutting_parameters(case))
        else:
            raise SystemDescriptionError(f"cutting_mode must be 'zmap' or 'path', got {options.cutting_mode!r}")
        system.add(cutting, rate=1)
        for a in AXES:
            system.connect(f"{a}_drive.table_position", f"cutting.{a}_position")   # tool vs workpiece
        system.connect("nck.spindle_speed", "cutting.spindle_speed")
        if case.tools:  # a tool table: the cutter of the tool in the spindle (without one, the one [tool])
            system.connect("nck.tool", "cutting.tool")
            _check_tools_listed(case, nck)
        # step-mean forces: instantaneous samples at 1 ms would alias the tooth frequency
        system.connect("cutting.fx_mean", "x_drive.disturbance_force")
        system.connect("cutting.fy_mean", "y_drive.disturbance_force")
        # the end edges' thrust (already a step mean): Fd = fz <= 0, the slide pushed up (module docstring)
        system.connect("cutting.fz", "z_drive.disturbance_force")

    # The position loop samples the NC command of the current interpolation period, as a real
    # controller does: the MCU and drives step before the NC kernel advances. (The signal-flow
    # order would hand the MCU the next period's command, 1 ms early, and shrink the ramp
    # following error from v/Kp to v/Kp - v*h.)
    order = ["mcu", *(f"{a}_drive" for a in AXES), "nck"] + (["cutting"] if cutting is not None else [])
    system.set_execution_order(order)

    probes = twin_probes(system)
    stop_when = ("nck.done", "mcu.in_position")
    # a member whose axis runs away (unstable gains or friction a GA tried) is marked diverged:
    # 2 m is beyond any machining-center travel, 3x rapid beyond any commanded speed
    limits = {}
    for a in AXES:
        rapid = float(machine.si(f"axis.{a}")["rapid_feed"])
        limits[f"{a}_drive.position"] = (-2.0, 2.0)
        limits[f"{a}_drive.velocity"] = (-3.0 * rapid, 3.0 * rapid)
    return Twin(system, nck, mcu, drives, cutting, probes, options, stop_when, limits)


#: Recording channels of the twin: (channel, component.variable, unit), per recording.md plus extras.
TWIN_CHANNELS: tuple[tuple[str, str, str], ...] = (
    ("line", "nck.line", "1"),
    *((f"{a}_ref_mm", f"nck.{a}_ref", "mm") for a in AXES),
    *((f"{a}_mm", f"{a}_drive.table_position", "mm") for a in AXES),   # = motor-side position without effects
    *((f"{a}_tcmd_A", f"mcu.{a}_current_cmd", "A") for a in AXES),
    ("spindle_ref_rpm", "nck.spindle_ref", "rpm"),
    ("spindle_rpm", "cutting.spindle_speed_actual", "rpm"),   # nck.spindle_speed without cutting (_FALLBACK)
    ("fx_N", "cutting.fx", "N"),
    ("fy_N", "cutting.fy", "N"),
    ("fz_N", "cutting.fz", "N"),   # the end edges' thrust (axial chip, fmus_src.cutting.axial)
    ("fc_N", "cutting.fc", "N"),
    ("fc_peak_N", "cutting.fc_peak", "N"),
    ("spindle_torque_Nm", "cutting.spindle_torque", "N.m"),
    ("spindle_power_W", "cutting.spindle_power", "W"),
    ("mrr_mm3_per_min", "cutting.mrr", "mm3/min"),
    ("feed_mm_per_min", "nck.feed_ref", "mm/min"),
    ("tool", "nck.tool", "1"),   # the tool in the spindle (T number of the last M6, 0 before): the cost per tool
)


#: Where to find a channel's signal when its usual source is a foreign component with other names:
#: the output wired into this input.
_CONSUMER_OF: dict[str, str] = {
    **{f"{a}_drive.table_position": f"mcu.{a}_position" for a in AXES},
    **{f"mcu.{a}_current_cmd": f"{a}_drive.current_cmd" for a in AXES},
    **{f"nck.{a}_ref": f"mcu.{a}_ref" for a in AXES},
}


#: Source of a channel when its usual source is absent (no cutting component, or a cutting FMU
#: without the output: the spindle runs at the NC kernel's speed).
_FALLBACK: dict[str, str] = {"cutting.spindle_speed_actual": "nck.spindle_speed"}


def _provides(system: System, reference: str) -> bool:
    comp, var = reference.split(".")
    if comp not in system.components:
        return False
    try:
        system.components[comp].variable(var)
    except CncTwinError:
        return False
    return True


def twin_probes(system: System) -> list[Probe]:
    """The twin's recording channels that ``system`` can provide.

    A channel whose usual variable is missing (a foreign FMU with other
    names) is taken from the output wired into the input that consumes it,
    e.g. ``x_mm`` from whatever feeds ``mcu.x_position``, converted to mm.
    """
    feeds = {c.target: c.source for c in system.connections}
    probes = []
    for channel, reference, unit in TWIN_CHANNELS:
        if reference in _FALLBACK and not _provides(system, reference):
            reference = _FALLBACK[reference]
        comp, var = reference.split(".")
        if comp not in system.components:
            continue
        try:
            system.components[comp].variable(var)
        except CncTwinError:
            reference = feeds.get(_CONSUMER_OF.get(reference, ""), "")
            if not reference:
                continue
        probes.append(Probe(channel, reference, unit))
    return probes


def write_twin_ssp(case: Case, ssd_path: Path, ssv_path: Path | None = None, options: TwinOptions | None = None) -> tuple[Path, Path]:
    """Describe the twin of ``case`` as SSP 1.0: structure (``.ssd``) and parameter values (``.ssv``).

    The machine file (TOML) stays the source of truth; this generates the SSP view of it.
    Element sources point at ``fmus/<Component>.fmu`` next to the SSD (``cnctwin build-fmus``).
    """
    from .master import MasterSettings
    from .ssp import system_to_ssp

    ssd_path = Path(ssd_path)
    ssv_path = Path(ssv_path) if ssv_path is not None else ssd_path.with_suffix(".ssv")
    twin = build_twin(case, batch=1, options=options)
    settings = MasterSettings(step=twin.options.step, stop_when=twin.stop_when, limits=twin.limits or {})
    return system_to_ssp(twin.system, ssd_path, ssv_path, settings)


def reference_path(case: Case, options: TwinOptions | None = None, program_text: str | None = None) -> np.ndarray:
    """Tool-tip path of the nominal program (NC reference after acc/dec), m, shape (K, 3).

    Samples closer than 1 µm to the previous kept one are dropped, so the
    path is a polyline in travel order starting at the start position.
    """
    return reference_path_and_tools(case, options, program_text)[0]


def reference_path_and_tools(case: Case, options: TwinOptions | None = None, program_text: str | None = None
                             ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`reference_path` and the tool in the spindle at each of its points (T number, shape (K,) int).

    A kept point's tool is the one in the spindle when the reference reached it (after an M6 the tool-change
    position keeps the old tool; the first point after it has the new one).
    """
    options = options or TwinOptions()
    start = np.asarray(options.start_mm, dtype=float) * 1e-3
    params = nck_parameters(case.machine)
    params.update(case.offsets.nck_parameters())
    params.update({f"{a}_initial": start[i] for i, a in enumerate(AXES)})
    nck = NCKernel("nck", batch=1, program_file=str(case.program), **params)
    if program_text is not None:
        nck.set_program_text(program_text, str(case.program))
    nck.setup(0.0)
    plan = nck.plan_.member(0)
    samples = plan.position
    keep = [0]
    for k in range(1, len(samples)):
        if np.linalg.norm(samples[k] - samples[keep[-1]]) > 1e-6:
            keep.append(k)
    return samples[keep], np.asarray(plan.tool, dtype=np.int64)[keep]


def engagement_table(case: Case, options: TwinOptions | None = None, program_text: str | None = None) -> EngagementTable:
    """Engagement along the nominal program's path, computed once (for ``cutting_mode="path"``).

    The table depends only on the reference path and the tool and stock parameters: an earlier table of the
    same content is returned (:func:`orchestrator.memo.remember`; the reference pass takes about 3 s on the
    diagnosis tests' short programs, a diagnosis of a dynamometer file needed it three times).

    A case whose tool table lists a cutter other than ``[tool]`` (:meth:`~orchestrator.case.Case.several_tools`)
    gets the cutter of each path point (:meth:`~orchestrator.case.Case.tool_for` of the tool in the spindle
    there): each station is swept, and later cut, with its own cutter (:mod:`fmus_src.cutting.table`).
    """
    if case.stock is None:
        raise SystemDescriptionError(f"{case.program}: an engagement table needs a stock (the case has none)")
    path, tools = reference_path_and_tools(case, options, program_text)
    params = cutting_parameters(case)
    cutters = None
    if case.several_tools():
        used = {int(t): case.tool_for(int(t)) for t in np.unique(tools)}
        cutters = (np.array([used[int(t)].diameter_mm * 1e-3 for t in tools]),
                   np.array([used[int(t)].flutes for t in tools], dtype=np.int64))
    key = digest(path, {k: v for k, v in params.items() if k == "tool_diameter" or k.startswith("stock_")},
                 *(() if cutters is None else cutters))
    return remember("engagement_table", key, lambda: EngagementTable.from_parameters(path, params, cutters=cutters))
