"""Case folders: ``case.toml`` + program + recording, per ``shared/spec/recording.md``.

Paths inside ``case.toml`` are relative to the case folder. Errors name the
file, the line and the field.
"""
from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fmus_src.cutting.tool_table import N_TOOL_TABLE
from fmus_src.nck.component import N_TOOL_LENGTHS, N_TOOL_RADII
from fmus_src.nck.input_ranges import MAX_TOOL

from .errors import CncTwinError
from .machine import Machine, MachineFileError, _line_of, load_machine, resolve_machine_path

_TOP_KEYS = {"program", "recording", "stock", "tool", "tools", "machine", "material", "offsets"}
_SECTION_KEYS = {
    "stock": {"min", "max"},
    "tool": {"diameter_mm", "flutes", "price_KRW", "taylor_C", "taylor_n"},
    "machine": {"parameters"},
    "offsets": {"radius_mm", "length_mm"},
}
#: Stock coordinates beyond this (mm, work coordinates) are out of any machining center's reach.
MAX_STOCK_COORDINATE_MM = 10_000.0
#: Smallest tool diameter, mm: the smallest micro end mills (10 um).
MIN_TOOL_DIAMETER_MM = 0.01
#: Most tools a case's tool table (``[tools.T<n>]``) lists: the cutting load's table slots.
MAX_CASE_TOOLS = N_TOOL_TABLE
#: ``[offsets]`` key -> (NC kernel parameter prefix, address, number of registers).
_OFFSET_TABLES = {"radius_mm": ("tool_radius", "D", N_TOOL_RADII), "length_mm": ("tool_length", "H", N_TOOL_LENGTHS)}


class CaseError(CncTwinError):
    """A case folder or ``case.toml`` is missing something or is malformed."""


@dataclass(frozen=True)
class Stock:
    """Workpiece block in work coordinates, mm."""

    min_mm: tuple[float, float, float]
    max_mm: tuple[float, float, float]


#: Optional cost keys of ``[tool]`` / ``[tools.T<n>]`` -> (what is expected, lowest, lowest allowed, highest).
_COST_KEYS = {
    "price_KRW": ("a price in KRW per tool, >= 0", 0.0, True, math.inf),
    "taylor_C": ("the Taylor constant C in m/min (cutting speed for a 1 min life), > 0", 0.0, False, math.inf),
    "taylor_n": ("the Taylor exponent n, > 0 and <= 1", 0.0, False, 1.0),
}


@dataclass(frozen=True)
class Tool:
    """Flat end mill, and what it costs.

    Attributes
    ----------
    diameter_mm : float
        Cutter diameter, mm.
    flutes : int
        Number of teeth.
    price_KRW : float or None
        Pt, KRW per tool (None: the machine file's ``[cost] tool_price_KRW``).
    taylor_C, taylor_n : float or None
        Taylor constant (m/min) and exponent of the tool life (None: the machine file's ``[cost]``).
    """

    diameter_mm: float = 6.0
    flutes: int = 2
    price_KRW: float | None = None
    taylor_C: float | None = None
    taylor_n: float | None = None

    def same_cutter(self, other: "Tool") -> bool:
        """Whether ``other`` has this tool's geometry (diameter and teeth; its cost keys aside)."""
        return (self.diameter_mm, self.flutes) == (other.diameter_mm, other.flutes)


@dataclass(frozen=True)
class ToolOffsets:
    """The control's tool offset memory as the case states it (``[offsets]`` in case.toml), mm.

    Attributes
    ----------
    radius_mm : dict int -> float
        Tool radius offsets D1..D200 (geometry + wear) used by G41/G42; registers not given are 0.
    length_mm : dict int -> float
        Tool length offsets H1..H200 used by G43/G44; registers not given are 0.
    """

    radius_mm: dict[int, float] = field(default_factory=dict)
    length_mm: dict[int, float] = field(default_factory=dict)

    def nck_parameters(self) -> dict[str, float]:
        """The NC kernel parameters ``tool_radius_<n>`` / ``tool_length_<n>`` (m) of the given registers."""
        out = {f"tool_radius_{n}": v * 1e-3 for n, v in self.radius_mm.items()}
        out.update({f"tool_length_{n}": v * 1e-3 for n, v in self.length_mm.items()})
        return out


@dataclass
class Case:
    """A loaded case.

    Attributes
    ----------
    folder : Path
        The case folder (or the folder of the program when there is no case file).
    program : Path
        G-code program.
    recording : Path or None
        Measured or simulated recording, when the case has one.
    stock : Stock or None
        Workpiece block; None means an air cut.
    tool : Tool
        Cutter (default: 6 mm, 2 flutes as in the paper): the tool of every T number that ``tools`` does not
        list, and of a program without T words.
    machine : Machine
        Machine parameter set.
    material : str
        Material name in the machine file (default: its first material, A6061).
    offsets : ToolOffsets
        Tool radius (D) and length (H) offsets of the control (default: all 0, as CAM "wear"-mode posts need).
    tools : dict int -> Tool
        The tool table (``[tools.T<n>]`` of case.toml): the cutter of each listed T number (default: empty).
    tool_stated : bool
        Whether case.toml states ``[tool]`` (False: ``tool`` is the 6 mm, 2-flute default); with a tool table
        and no ``[tool]``, a program that changes to an unlisted tool is refused (:func:`unlisted_tool_error`).
    """

    folder: Path
    program: Path
    recording: Path | None
    stock: Stock | None
    tool: Tool
    machine: Machine
    material: str
    source: Path | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    offsets: ToolOffsets = field(default_factory=ToolOffsets)
    tools: dict[int, Tool] = field(default_factory=dict)
    tool_stated: bool = True

    def tool_for(self, number: int) -> Tool:
        """The cutter modelled for tool number ``number`` (the table's, else ``[tool]``)."""
        return self.tools.get(int(number), self.tool)

    def several_tools(self) -> bool:
        """Whether the tool table lists a cutter whose geometry differs from ``[tool]``'s (the cutting load then
        switches geometry at tool changes)."""
        return any(not t.same_cutter(self.tool) for t in self.tools.values())


def _vector(path: Path, text: str, section: str, key: str, value: Any) -> tuple[float, float, float]:
    line = _line_of(text, section, key)
    if not isinstance(value, list) or len(value) != 3 or not all(
        isinstance(v, (int, float)) and not isinstance(v, bool) for v in value
    ):
        raise CaseError(f"{path}:{line}: [{section}] {key} must be a list of 3 numbers in mm, got {value!r}")
    if not all(math.isfinite(v) for v in value):
        raise CaseError(f"{path}:{line}: [{section}] {key} must be finite, got {value!r}")
    return (float(value[0]), float(value[1]), float(value[2]))


def load_case(path: str | Path, machine_override: str | Path | None = None) -> Case:
    """Load a case folder or a ``case.toml`` file.

    Parameters
    ----------
    path : str or Path
        A case folder (containing ``case.toml``) or the ``case.toml`` itself.
    machine_override : str or Path, optional
        Machine set name or file that replaces the case's ``[machine] parameters``.

    Raises
    ------
    CaseError
        Missing file, invalid TOML, unknown or malformed field.
    """
    path = Path(path)
    toml_path = path / "case.toml" if path.is_dir() else path
    if not toml_path.is_file():
        raise CaseError(f"{toml_path}: case file not found (a case folder holds case.toml, program and recording)")
    try:
        text = toml_path.read_text(encoding="utf-8-sig")  # a BOM (Windows editors) is not TOML: dropped
    except UnicodeDecodeError as exc:
        raise CaseError(f"{toml_path}: not a UTF-8 text file (byte offset {exc.start}); expected a TOML case file") from None
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise CaseError(f"{toml_path}: not valid TOML: {exc}") from None
    except RecursionError:  # tomllib parses nested arrays and tables recursively
        raise CaseError(f"{toml_path}: arrays or tables nested too deeply to read; expected a TOML case file") from None
    folder = toml_path.parent
    for key, value in raw.items():
        if key not in _TOP_KEYS:
            raise CaseError(
                f"{toml_path}:{_line_of(text, key, None) or _find_top_key(text, key)}: unknown field {key!r}; "
                f"expected {sorted(_TOP_KEYS)}"
            )
        if key in _SECTION_KEYS:
            if not isinstance(value, dict):
                raise CaseError(f"{toml_path}:{_find_top_key(text, key)}: {key!r} must be a table [{key}]")
            unknown = set(value) - _SECTION_KEYS[key]
            if unknown:
                bad = sorted(unknown)[0]
                raise CaseError(
                    f"{toml_path}:{_line_of(text, key, bad)}: unknown field {bad!r} in [{key}]; "
                    f"expected {sorted(_SECTION_KEYS[key])}"
                )

    program_value = raw.get("program")
    if not isinstance(program_value, str) or not program_value:
        raise CaseError(f"{toml_path}:{_find_top_key(text, 'program')}: 'program' must name the G-code file")
    program = _file_in_case(toml_path, text, "program", folder / program_value)
    recording = None
    if "recording" in raw:
        if not isinstance(raw["recording"], str) or not raw["recording"]:
            raise CaseError(f"{toml_path}:{_find_top_key(text, 'recording')}: 'recording' must name the recording "
                            f"file (a CSV per recording.md), got {raw['recording']!r}")
        recording = _file_in_case(toml_path, text, "recording", folder / raw["recording"])

    stock = None
    if "stock" in raw:
        for key in ("min", "max"):
            if key not in raw["stock"]:
                raise CaseError(f"{toml_path}:{_line_of(text, 'stock', None)}: [stock] needs {key!r} = [x, y, z] in mm")
        lo = _vector(toml_path, text, "stock", "min", raw["stock"]["min"])
        hi = _vector(toml_path, text, "stock", "max", raw["stock"]["max"])
        for key, vec in (("min", lo), ("max", hi)):
            if not all(abs(v) <= MAX_STOCK_COORDINATE_MM for v in vec):
                raise CaseError(f"{toml_path}:{_line_of(text, 'stock', key)}: [stock] {key} = {list(vec)} mm lies "
                                f"beyond +-{MAX_STOCK_COORDINATE_MM:g} mm; expected work coordinates in mm")
        if not all(a < b for a, b in zip(lo, hi)):
            raise CaseError(
                f"{toml_path}:{_line_of(text, 'stock', 'max')}: [stock] max {hi} must exceed min {lo} on every axis"
            )
        stock = Stock(lo, hi)

    tool = _tool(toml_path, text, "tool", raw["tool"]) if "tool" in raw else Tool()
    tools = _tools(toml_path, text, raw["tools"]) if "tools" in raw else {}

    machine_ref: str | Path = "default"
    if "machine" in raw and "parameters" not in raw["machine"]:
        raise CaseError(f"{toml_path}:{_line_of(text, 'machine', None) or _find_top_key(text, 'machine')}: [machine] "
                        "needs 'parameters' (a set shipped in models/machines, e.g. \"default\", or a path to a "
                        "machine .toml file relative to the case folder)")
    if "machine" in raw and "parameters" in raw["machine"]:
        machine_ref = raw["machine"]["parameters"]
        if not isinstance(machine_ref, str):
            raise CaseError(f"{toml_path}:{_line_of(text, 'machine', 'parameters')}: [machine] parameters must be a string")
    if machine_override:
        machine = load_machine(machine_override, relative_to=folder)
    else:
        try:
            resolve_machine_path(machine_ref, relative_to=folder)
        except MachineFileError as exc:  # name the case file and field that point nowhere
            raise CaseError(f"{toml_path}:{_line_of(text, 'machine', 'parameters')}: [machine] parameters = "
                            f"{machine_ref!r}: {exc}; expected a shipped set name or a .toml path (relative to "
                            f"the case folder)") from None
        machine = load_machine(machine_ref, relative_to=folder)

    materials = machine.materials()
    material = raw.get("material", materials[0] if materials else "")
    if materials and material not in materials:
        raise CaseError(
            f"{toml_path}:{_find_top_key(text, 'material')}: material {material!r} is not in {machine.path}; "
            f"it defines {materials}"
        )
    offsets = _offsets(toml_path, text, raw["offsets"]) if "offsets" in raw else ToolOffsets()
    return Case(folder, program, recording, stock, tool, machine, material, toml_path, offsets=offsets, tools=tools,
                tool_stated="tool" in raw)


def _tool(path: Path, text: str, section: str, t: dict[str, Any]) -> Tool:
    """``[tool]`` or ``[tools.T<n>]`` (``section``) -> :class:`Tool`; both geometry keys required, the optional
    cost keys (``price_KRW``, ``taylor_C``, ``taylor_n``) checked."""
    diameter = t.get("diameter_mm", Tool.diameter_mm)
    flutes = t.get("flutes", Tool.flutes)
    if isinstance(diameter, bool) or not isinstance(diameter, (int, float)) \
            or not MIN_TOOL_DIAMETER_MM <= diameter < 1000:
        raise CaseError(
            f"{path}:{_line_of(text, section, 'diameter_mm')}: [{section}] diameter_mm must be a number in mm "
            f"from {MIN_TOOL_DIAMETER_MM:g} (the smallest micro end mills) to below 1000, got {diameter!r}"
        )
    if isinstance(flutes, bool) or not isinstance(flutes, int) or not 1 <= flutes <= 24:
        raise CaseError(
            f"{path}:{_line_of(text, section, 'flutes')}: [{section}] flutes must be a whole number 1..24, "
            f"got {flutes!r}"
        )
    for key in ("diameter_mm", "flutes"):  # a tool table states the cutter: a key left out is not guessed
        if key not in t:
            raise CaseError(f"{path}:{_line_of(text, section, None)}: [{section}] needs {key!r} "
                            f"({'the cutter diameter in mm' if key == 'diameter_mm' else 'the number of teeth'}); "
                            + (f"without a [tool] table the case uses {Tool.diameter_mm:g} mm, {Tool.flutes} flutes"
                               if section == "tool" else "each listed tool states both"))
    cost: dict[str, float] = {}
    for key, (expected, low, low_ok, high) in _COST_KEYS.items():
        if key not in t:
            continue
        value = t[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                or not (value >= low if low_ok else value > low) or value > high:
            raise CaseError(f"{path}:{_line_of(text, section, key)}: [{section}] {key} must be {expected}, "
                            f"got {value!r}")
        cost[key] = float(value)
    return Tool(float(diameter), int(flutes), **cost)


def _tools(path: Path, text: str, table: Any) -> dict[int, Tool]:
    """``[tools.T1]``, ``[tools.T2]``, ... -> ``{1: Tool, 2: Tool}`` (names, keys and values checked)."""
    line = _line_of(text, "tools", None) or _find_top_key(text, "tools")
    if not isinstance(table, dict):
        raise CaseError(f"{path}:{line}: 'tools' must be a table of tools, e.g. [tools.T2] with diameter_mm and "
                        f"flutes, got {table!r}")
    out: dict[int, Tool] = {}
    for name, entry in table.items():
        match = re.fullmatch(r"T(\d+)", name)
        where = _line_of(text, f"tools.{name}", None) or line
        if match is None or not 1 <= int(match.group(1)) <= MAX_TOOL:
            raise CaseError(f"{path}:{where}: unknown tool {name!r} in [tools]; expected T<n> with n = 1..{MAX_TOOL} "
                            "(the T word of the program's M6), e.g. [tools.T2]")
        section = f"tools.{name}"
        if not isinstance(entry, dict):
            raise CaseError(f"{path}:{where}: {section!r} must be a table [{section}] with diameter_mm and flutes, "
                            f"got {entry!r}")
        unknown = set(entry) - _SECTION_KEYS["tool"]
        if unknown:
            bad = sorted(unknown)[0]
            raise CaseError(f"{path}:{_line_of(text, section, bad)}: unknown field {bad!r} in [{section}]; "
                            f"expected {sorted(_SECTION_KEYS['tool'])}")
        number = int(match.group(1))
        if number in out:  # T02 and T2 are one tool
            raise CaseError(f"{path}:{where}: [{section}] lists T{number} a second time; expected each tool once")
        out[number] = _tool(path, text, section, entry)
    if len(out) > MAX_CASE_TOOLS:
        raise CaseError(f"{path}:{line}: [tools] lists {len(out)} tools; the cutting load holds at most "
                        f"{MAX_CASE_TOOLS} (list the tools the program uses)")
    return dict(sorted(out.items()))


def unlisted_tool_error(case: Case, changes: list[tuple[int, int]]) -> str | None:
    """Why the program cannot run on the case's tool table, or None.

    Parameters
    ----------
    case : Case
        The case (its ``tools`` and whether it states ``[tool]``).
    changes : list of (int, int)
        ``(line, tool)`` of every M6 of the program, in execution order.

    Returns
    -------
    str or None
        With a tool table and no ``[tool]``, the first M6 to a tool the table does not list, naming the
        program file and line and the case file; None otherwise (``[tool]`` covers every unlisted tool).
    """
    if case.tool_stated or not case.tools:
        return None
    for line, number in changes:
        if int(number) not in case.tools:
            listed = ", ".join(f"T{n}" for n in case.tools)
            return (f"{case.program}:{line}: M6 changes to T{number}, which {case.source or case.folder} does not "
                    f"list (its [tools] has {listed} and it has no [tool] for the others); expected a "
                    f"[tools.T{number}] table with diameter_mm and flutes, or a [tool] for every unlisted tool")
    return None


def _offsets(path: Path, text: str, table: dict[str, Any]) -> ToolOffsets:
    """``[offsets] radius_mm = { 1 = 3.0 }, length_mm = { 1 = 120.5 }`` -> :class:`ToolOffsets` (keys checked)."""
    tables: dict[str, dict[int, float]] = {}
    for key, (_, address, count) in _OFFSET_TABLES.items():
        line = _line_of(text, "offsets", key)
        value = table.get(key, {})
        if not isinstance(value, dict):
            raise CaseError(f"{path}:{line}: [offsets] {key} must be a table of register numbers, e.g. "
                            f"{key} = {{ 1 = 3.0 }}, got {value!r}")
        regs: dict[int, float] = {}
        for number, v in value.items():
            if not number.isdigit() or not 1 <= int(number) <= count:
                raise CaseError(f"{path}:{line}: [offsets] {key}: unknown register {number!r}; expected "
                                f"{address} numbers 1..{count}")
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or abs(v) >= 1000:
                raise CaseError(f"{path}:{line}: [offsets] {key}: {address}{number} must be a number in mm "
                                f"(|value| < 1000), got {v!r}")
            regs[int(number)] = float(v)
        tables[key] = regs
    return ToolOffsets(tables["radius_mm"], tables["length_mm"])


def case_for_program(program: str | Path, machine: str | Path = "default") -> Case:
    """A case for a bare program: air cut (no stock), default tool, given machine."""
    program = Path(program)
    m = load_machine(machine)
    materials = m.materials()
    return Case(program.parent, program, None, None, Tool(), m, materials[0] if materials else "")


def missing_file(case: Case, key: str) -> str | None:
    """Why the file that ``key`` (``"program"`` or ``"recording"``) of a case names cannot be read, or None.

    The message names case.toml, the line of the field and the file, e.g.
    ``case.toml:1: program = "part.nc": file /cases/a/part.nc not found``.
    """
    path = case.program if key == "program" else case.recording
    if path is None or Path(path).is_file():
        return None
    where = str(case.source or case.folder)
    if case.source is not None and Path(case.source).is_file():
        try:
            text = Path(case.source).read_text(encoding="utf-8-sig")
            value = tomllib.loads(text).get(key)
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
            text, value = "", None
        if isinstance(value, str) and (Path(case.folder) / value) == Path(path):
            return f"{where}:{_find_top_key(text, key)}: {key} = {value!r}: file {path} not found"
    return f"{where}: {key}: file {path} not found"


def _file_in_case(toml_path: Path, text: str, key: str, path: Path) -> Path:
    """``path``, named by the top-level ``key`` of case.toml; a folder there is an error naming file, line and field.

    A missing file is not an error here: ``simulate --case DIR PROGRAM`` replaces the case's program, and a
    command that needs a file says so when it reads it.
    """
    if path.is_dir():
        raise CaseError(f"{toml_path}:{_find_top_key(text, key)}: {key!r} names the folder {path}; expected a file "
                        f"(a path relative to the case folder, or absolute)")
    return path


def _find_top_key(text: str, key: str) -> int:
    for i, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if stripped.startswith(key) and stripped[len(key):].lstrip().startswith(("=", ".")):
            return i
    return 1
