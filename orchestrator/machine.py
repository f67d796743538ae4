"""Machine parameter sets: TOML files with units in the key names and provenance.

A machine file (see ``models/machines/default.toml``) holds values as inline
tables ``{ value = ..., source = "..." }`` or as bare values. Keys carry their
unit (``screw_lead_mm``); :meth:`Machine.si` returns a section converted to SI
with the suffix stripped (``{"screw_lead": 0.012}``), which is what the
component parameters expect.

Every key is checked against :data:`SCHEMA`; an unknown or missing key is a
:class:`MachineFileError` naming the file, the line and what was expected.

The optional section ``[nck.m_codes]`` maps the machine builder's M codes to the standard ones
(``13 = { means = [3, 8], source = "..." }``; rules: :mod:`fmus_src.nck.m_aliases`); :meth:`Machine.m_codes`
returns it.
"""
from __future__ import annotations

import copy
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fmus_src.nck.cycles import BORING_SHIFTS
from fmus_src.nck.decimal_input import DECIMAL_INPUTS
from fmus_src.nck.m_aliases import ALIAS_TARGETS, alias_problem
from fmus_src.nck.params import FILTER_KINDS, MIN_POSITION_GAIN
from fmus_src.nck.settings import TOOL_CHANGE_RETRACTS, TOOL_CHANGE_SPINDLES
from fmus_src.units import UnitError, split_unit_suffix, to_si

from .errors import CncTwinError

MODELS_DIR = Path(__file__).resolve().parent.parent / "models"
MACHINES_DIR = MODELS_DIR / "machines"

AXES = ("x", "y", "z")

_AXIS_KEYS = {
    "mass_kg", "torque_constant_Nm_per_A", "screw_lead_mm", "peak_current_A", "rapid_feed_mm_per_min",
    "position_gain_per_s", "velocity_p_gain_A_per_m_per_s", "velocity_i_gain_A_per_m",
    "position_scale", "velocity_p_scale", "velocity_i_scale",
    "velocity_feedforward", "acceleration_feedforward",
    "excess_error_in_motion_mm", "excess_error_at_stop_mm", "stroke_min_mm", "stroke_max_mm",
}
#: The stored stroke limits of an axis (FANUC No. 1321 / No. 1320), machine coordinates; optional, both or none.
STROKE_KEYS = ("stroke_min_mm", "stroke_max_mm")
_FRICTION_KEYS = {"coulomb_N", "static_N", "stribeck_velocity_m_per_s", "viscous_Ns_per_m"}
#: Effects the twin leaves out in the paper's baseline (all 0 = off); written by `cnctwin diagnose`.
_EFFECT_KEYS = {
    "gravity_force_N", "gravity_spring_N_per_mm", "reversal_friction_peak_N", "reversal_friction_decay_mm",
    "ripple_amplitude_N", "ripple_period_mm", "screw_stiffness_N_per_um", "backlash_width_um",
    "pitch_slope_um_per_m", "pitch_amplitude_um", "pitch_period_mm", "thermal_drift_rate_um_per_min",
    "servo_delay_ms",
}

#: Cutting-process effects the twin leaves out in the paper's baseline (all 0 = off; see the
#: "Cutting load" section of README.md for the component parameters they map to).
_CUTTING_EFFECT_KEYS = {
    "eccentricity_um", "phase_deg", "helix_deg", "kte_N_per_mm", "kre_N_per_mm", "tool_stiffness_N_per_um",
    "wear_rate_percent_per_min", "spindle_droop_rpm_per_Nm", "chatter_frequency_Hz", "chatter_damping_ratio",
    "chatter_stiffness_N_per_um",
}

#: Allowed keys per section. Section names are dotted paths; ``*`` matches any name.
SCHEMA: dict[str, set[str]] = {
    "machine": {"name", "description"},
    "nck": {
        "interpolation_period_ms", "lookahead_blocks", "max_cutting_feed_mm_per_min",
        "accel_before_interp_mm_per_s2", "accel_change_time_before_interp_ms",
        "corner_velocity_difference_mm_per_min", "arc_accel_mm_per_s2",
        "cutting_time_constant_ms", "cutting_filter", "rapid_time_constant_ms", "rapid_filter",
        "in_position_width_mm", "tool_change_time_s",
        "reference_x_mm", "reference_y_mm", "reference_z_mm", "g73_retract_mm", "g83_clearance_mm",
        *(f"reference{n}_{a}_mm" for n in (2, 3, 4) for a in AXES),
        "rigid_tapping_time_constant_ms", "rigid_tapping_mode", "boring_shift", "decimal_point_input",
        "tool_change_retract", "tool_change_spindle", *(f"machine_zero_{a}_mm" for a in AXES),
        "in_position_before_rapid",
    },
    "spindle": {"max_speed_rpm", "ramp_rpm_per_s", "speed_arrival_tolerance_percent", "power_kW"},
    "servo": {"position_loop_period_ms", "velocity_loop_period_ms"},
    **{f"axis.{a}": set(_AXIS_KEYS) for a in AXES},
    **{f"axis.{a}.friction.{d}": set(_FRICTION_KEYS) for a in AXES for d in ("positive", "negative")},
    **{f"axis.{a}.effects": set(_EFFECT_KEYS) for a in AXES},
    "material.*": {"kt_N_per_m2", "ke", "ka"},
    "cutting.effects": set(_CUTTING_EFFECT_KEYS),
    "cost": {
        "tool_price_KRW", "tool_change_time_s", "labor_KRW_per_s", "depreciation_KRW_per_s",
        "taylor_n", "taylor_C",
    },
}

#: The optional section of M-code aliases: ``<builder's M code> = { means = [<standard M codes>], source = "..." }``.
M_CODES_SECTION = "nck.m_codes"

#: Keys that may be left out of a machine file (the component default is used).
OPTIONAL_SECTIONS: set[str] = {"machine", "material.*", *(f"axis.{a}.effects" for a in AXES), "cutting.effects"}
#: Keys of required sections that may be left out (the component default, equal in effect to default.toml's
#: value, is used; the reference positions of a file with machine_zero_*_mm: 0, machine zero): keys added after
#: machine files were written, so that a user's older file still loads.
OPTIONAL_KEYS: dict[str, set[str]] = {
    "nck": {"reference_x_mm", "reference_y_mm", "reference_z_mm", "g73_retract_mm", "g83_clearance_mm",
            *(f"reference{n}_{a}_mm" for n in (2, 3, 4) for a in AXES),
            "rigid_tapping_time_constant_ms", "rigid_tapping_mode", "boring_shift", "decimal_point_input",
            "tool_change_retract", "tool_change_spindle", *(f"machine_zero_{a}_mm" for a in AXES),
            "in_position_before_rapid"},
    **{f"axis.{a}": set(STROKE_KEYS) for a in AXES},
}
#: Where machine zero sits in the twin's axis frame (mm), optional, all three or none: the axis frame is the work
#: coordinate system of the default work offsets (G54..G59 = -machine zero), and machine coordinates (G53, the
#: reference positions, stroke limits, work offsets) are axis frame - machine zero. Without them machine
#: coordinates are the axis frame (the frame of files written before these keys).
MACHINE_ZERO_KEYS = tuple(f"machine_zero_{a}_mm" for a in AXES)


class MachineFileError(CncTwinError):
    """A machine parameter file is missing, malformed or has unknown keys."""


def _positive(v: float) -> bool:
    return v > 0.0


def _non_negative(v: float) -> bool:
    return v >= 0.0


_GT0 = (_positive, "a number > 0")
_GE0 = (_non_negative, "a number >= 0")
_GE0_OFF = (_non_negative, "a number >= 0 (0 = off)")

#: Allowed words of the text values, by section kind (``axis.*``: any axis) and key; None: any text.
TEXT_VALUES: dict[tuple[str, str], tuple[str, ...] | None] = {
    ("machine", "name"): None,
    ("machine", "description"): None,
    ("nck", "cutting_filter"): FILTER_KINDS,
    ("nck", "rapid_filter"): FILTER_KINDS,
    ("nck", "rigid_tapping_mode"): ("M29", "always"),
    ("nck", "boring_shift"): tuple(sorted(BORING_SHIFTS)),
    ("nck", "decimal_point_input"): DECIMAL_INPUTS,
    ("nck", "tool_change_retract"): TOOL_CHANGE_RETRACTS,
    ("nck", "tool_change_spindle"): TOOL_CHANGE_SPINDLES,
    ("nck", "in_position_before_rapid"): ("on", "off"),
}
#: Range of the numeric values (file units) that the components accept (any other key: any finite number),
#: by section kind and key: (test, what is expected). Checked at load so that the error names the file and line.
VALUE_RULES: dict[tuple[str, str], tuple[Any, str]] = {
    **{("nck", k): _GT0 for k in (
        "interpolation_period_ms", "max_cutting_feed_mm_per_min", "accel_before_interp_mm_per_s2",
        "corner_velocity_difference_mm_per_min", "arc_accel_mm_per_s2", "in_position_width_mm")},
    **{("nck", k): _GE0 for k in (
        "accel_change_time_before_interp_ms", "cutting_time_constant_ms", "rapid_time_constant_ms",
        "tool_change_time_s", "rigid_tapping_time_constant_ms", "g73_retract_mm", "g83_clearance_mm")},
    ("nck", "lookahead_blocks"): (lambda v: v >= 1 and float(v).is_integer(), "a whole number >= 1"),
    **{("spindle", k): _GT0 for k in ("max_speed_rpm", "ramp_rpm_per_s", "power_kW")},
    ("spindle", "speed_arrival_tolerance_percent"): (lambda v: 0.0 <= v < 100.0, "a percentage in [0, 100)"),
    **{("servo", k): _GT0 for k in ("position_loop_period_ms", "velocity_loop_period_ms")},
    **{("axis.*", k): _GT0 for k in (
        "mass_kg", "torque_constant_Nm_per_A", "screw_lead_mm", "peak_current_A", "rapid_feed_mm_per_min",
        "position_gain_per_s", "velocity_p_gain_A_per_m_per_s", "position_scale", "velocity_p_scale")},
    **{("axis.*", k): _GE0 for k in ("velocity_i_gain_A_per_m", "velocity_i_scale")},
    **{("axis.*", k): _GE0_OFF for k in ("excess_error_in_motion_mm", "excess_error_at_stop_mm")},
    **{("axis.*.friction.*", k): (_non_negative, "a magnitude >= 0")
       for k in ("coulomb_N", "static_N", "viscous_Ns_per_m")},
    ("axis.*.friction.*", "stribeck_velocity_m_per_s"): _GT0,
    **{("axis.*.effects", k): _GE0_OFF for k in (
        "reversal_friction_decay_mm", "ripple_period_mm", "screw_stiffness_N_per_um", "backlash_width_um",
        "pitch_period_mm", "servo_delay_ms")},
    **{("cutting.effects", k): _GE0_OFF for k in (
        "eccentricity_um", "kte_N_per_mm", "kre_N_per_mm", "tool_stiffness_N_per_um", "wear_rate_percent_per_min",
        "spindle_droop_rpm_per_Nm", "chatter_frequency_Hz", "chatter_stiffness_N_per_um")},
    ("cutting.effects", "helix_deg"): (lambda v: abs(v) < 80.0, "an angle in deg with |helix| < 80"),
    ("cutting.effects", "chatter_damping_ratio"): (lambda v: 0.0 <= v < 1.0, "a damping ratio in [0, 1)"),
    ("material.*", "kt_N_per_m2"): _GE0,
    ("material.*", "ka"): _GE0,
    **{("cost", k): _GE0 for k in ("tool_price_KRW", "tool_change_time_s", "labor_KRW_per_s",
                                   "depreciation_KRW_per_s")},
    **{("cost", k): _GT0 for k in ("taylor_n", "taylor_C")},
}
#: Shortest internal drive step (s) a machine file may imply (:func:`fmus_src.servo.step_cap.stribeck_step_cap`):
#: 25 000 RK4 substeps per 250 us velocity-loop tick. Below it a run takes hours of wall time per second.
MIN_DRIVE_STEP_S = 1e-8


def _section_kind(section: str) -> str:
    """``axis.x.friction.positive`` -> ``axis.*.friction.*``, ``material.A6061`` -> ``material.*``."""
    parts = section.split(".")
    if parts[0] == "axis" and len(parts) >= 2:
        parts[1] = "*"
        if len(parts) == 4 and parts[2] == "friction":
            parts[3] = "*"
    elif parts[0] == "material" and len(parts) == 2:
        parts[1] = "*"
    return ".".join(parts)


def _value_problem(section: str, key: str, value: Any) -> str | None:
    """What is wrong with a leaf value of the schema (None when it is fine)."""
    kind = (_section_kind(section), key)
    if kind in TEXT_VALUES:
        words = TEXT_VALUES[kind]
        if not isinstance(value, str):
            return f"must be text in quotes{f' among {list(words)}' if words else ''}, got {value!r}"
        if words is not None and value not in words:
            return f"must be one of {list(words)}, got {value!r}"
        return None
    if isinstance(value, str):
        return f"must be a number (a string is not converted to the key's unit), got {value!r}"
    test, expected = VALUE_RULES.get(kind, (None, ""))
    if test is not None and not test(value):
        return f"must be {expected}, got {value!r}"
    return None


@dataclass
class Machine:
    """A loaded machine parameter set.

    Attributes
    ----------
    path : Path
        File it was read from.
    values : dict
        Nested tables of plain values in the file's units (provenance removed).
    provenance : dict[str, str]
        Dotted key → source text, for every value that had one.
    """

    path: Path
    values: dict[str, Any]
    provenance: dict[str, str] = field(default_factory=dict)

    @property
    def name(self) -> str:
        """Name of the parameter set (``[machine] name``, else the file stem)."""
        return str(self.values.get("machine", {}).get("name", self.path.stem))

    def table(self, section: str) -> dict[str, Any]:
        """Plain values of a dotted section in file units (sub-tables excluded)."""
        node: Any = self.values
        for part in section.split("."):
            if not isinstance(node, dict) or part not in node:
                raise MachineFileError(f"{self.path}: no section [{section}]")
            node = node[part]
        return {k: v for k, v in node.items() if not isinstance(v, dict)}

    def si(self, section: str) -> dict[str, float | str]:
        """Values of a dotted section converted to SI, unit suffix stripped from the keys.

        Examples
        --------
        >>> load_machine("default").si("axis.x")["screw_lead"]
        0.012
        """
        out: dict[str, float | str] = {}
        for key, value in self.table(section).items():
            name, symbol = split_unit_suffix(key)
            out[name] = value if isinstance(value, str) else to_si(float(value), symbol)
        return out

    def with_values(self, section: str, **values: float) -> "Machine":
        """A copy with some values of ``section`` replaced (keys with unit suffix, file units)."""
        new = Machine(self.path, copy.deepcopy(self.values), dict(self.provenance))
        node = new.values
        for part in section.split("."):
            node = node.setdefault(part, {})
        allowed = _allowed_keys(section)
        for key, value in values.items():
            if allowed is not None and key not in allowed:
                raise MachineFileError(f"[{section}] has no key {key!r}; expected one of {sorted(allowed)}")
            node[key] = value
        return new

    def has_section(self, section: str) -> bool:
        """Whether the dotted section exists in this file."""
        node: Any = self.values
        for part in section.split("."):
            if not isinstance(node, dict) or part not in node:
                return False
            node = node[part]
        return isinstance(node, dict)

    def m_codes(self) -> dict[int, tuple[int, ...]]:
        """The M-code aliases of ``[nck.m_codes]``: builder's M code -> the standard M codes it stands for (empty
        when the file has no such section)."""
        table = self.values.get("nck", {}).get("m_codes", {})
        return {int(code): tuple(means) for code, means in table.items()}

    def machine_zero(self) -> tuple[float, float, float] | None:
        """Where machine zero sits in the axis frame, m (``[nck] machine_zero_{x,y,z}_mm``); None without them."""
        nck = self.values.get("nck", {})
        if not all(k in nck for k in MACHINE_ZERO_KEYS):
            return None
        return tuple(to_si(float(nck[k]), "mm") for k in MACHINE_ZERO_KEYS)  # type: ignore[return-value]

    def stroke_limits(self) -> dict[str, tuple[float, float]]:
        """The stored stroke limits of the axes that have them: axis letter -> (minimum, maximum), m.

        ``[axis.<a>] stroke_min_mm`` / ``stroke_max_mm`` (FANUC No. 1321 / No. 1320, machine coordinates); an axis
        without them is left out (not checked).
        """
        out: dict[str, tuple[float, float]] = {}
        for a in AXES:
            sec = self.si(f"axis.{a}")
            if "stroke_min" in sec and "stroke_max" in sec:
                out[a] = (float(sec["stroke_min"]), float(sec["stroke_max"]))
        return out

    def materials(self) -> list[str]:
        """Names of the materials defined in the file."""
        return sorted(self.values.get("material", {}))


def _allowed_keys(section: str) -> set[str] | None:
    if section in SCHEMA:
        return SCHEMA[section]
    for pattern, keys in SCHEMA.items():
        if pattern.endswith(".*") and section.startswith(pattern[:-1]) and section.count(".") == pattern.count("."):
            return keys
    return None


def _line_of(text: str, section: str, key: str | None) -> int:
    """Best-effort 1-based line of ``key`` in ``[section]`` (0 when not found)."""
    lines = text.splitlines()
    header = re.compile(r"^\s*\[\s*" + re.escape(section) + r"\s*\]\s*(#.*)?$")
    start = next((i for i, line in enumerate(lines) if header.match(line)), None)
    if start is None:  # a dotted key (tool.flutes = 2) or an inline table (tool = { flutes = 2 })
        dotted = re.compile(r"^\s*" + re.escape(section).replace(r"\.", r"\s*\.\s*")
                            + (r"\s*\.\s*" + re.escape(key) if key else r"\s*[.=]"))
        inline = re.compile(r"^\s*" + re.escape(section) + r"\s*=\s*\{" + (r".*\b" + re.escape(key) + r"\s*=" if key else ""))
        return next((i + 1 for i, line in enumerate(lines) if dotted.match(line) or inline.match(line)), 0)
    if key is None:
        return start + 1
    pattern = re.compile(r"^\s*" + re.escape(key) + r"\s*=")
    for i in range(start + 1, len(lines)):
        if lines[i].lstrip().startswith("["):
            break
        if pattern.match(lines[i]):
            return i + 1
    return start + 1


def _flatten(path: Path, text: str, node: dict[str, Any], section: str, provenance: dict[str, str]) -> dict[str, Any]:
    """Strip ``{value, source}`` tables, validate keys, recurse into sub-sections."""
    out: dict[str, Any] = {}
    allowed = _allowed_keys(section) if section else set()
    for key, item in node.items():
        dotted = f"{section}.{key}" if section else key
        if dotted == M_CODES_SECTION and isinstance(item, dict):
            out[key] = _m_codes(path, text, item, provenance)
            continue
        is_leaf_table = isinstance(item, dict) and "value" in item and set(item) <= {"value", "source"}
        if isinstance(item, dict) and not is_leaf_table:
            if _allowed_keys(dotted) is None and not any(p.startswith(dotted + ".") for p in SCHEMA):
                raise MachineFileError(
                    f"{path}:{_line_of(text, dotted, None)}: unknown section [{dotted}]; "
                    f"expected sections {sorted(SCHEMA)}"
                )
            out[key] = _flatten(path, text, item, dotted, provenance)
            continue
        if allowed is None or key not in allowed:
            expected = sorted(allowed) if allowed else "no plain keys here"
            raise MachineFileError(
                f"{path}:{_line_of(text, section, key)}: unknown key {key!r} in [{section or 'top level'}]; "
                f"expected {expected}"
            )
        if is_leaf_table:
            value = item["value"]
            if "source" in item:
                provenance[dotted] = str(item["source"])
        else:
            value = item
        if isinstance(value, bool) or not isinstance(value, (int, float, str)):
            raise MachineFileError(
                f"{path}:{_line_of(text, section, key)}: [{section}] {key} must be a number or a string, got {value!r}"
            )
        if isinstance(value, (int, float)) and not math.isfinite(value):
            raise MachineFileError(f"{path}:{_line_of(text, section, key)}: [{section}] {key} is not finite")
        problem = _value_problem(section, key, value)
        if problem is not None:
            raise MachineFileError(f"{path}:{_line_of(text, section, key)}: [{section}] {key} {problem}")
        try:
            split_unit_suffix(key)
        except UnitError as exc:  # pragma: no cover - the schema only holds known suffixes
            raise MachineFileError(f"{path}: {exc}") from None
        out[key] = value
    return out


def _m_codes(path: Path, text: str, node: dict[str, Any], provenance: dict[str, str]) -> dict[str, list[int]]:
    """Validate ``[nck.m_codes]``: builder's M code -> ``{ means = [...], source = "..." }``."""
    out: dict[str, list[int]] = {}
    allowed = " ".join(str(c) for c in ALIAS_TARGETS)
    form = f'<M code> = {{ means = [<standard M codes among {allowed}>], source = "..." }}'
    for key, item in node.items():
        where = f"{path}:{_line_of(text, M_CODES_SECTION, key)}: [{M_CODES_SECTION}] {key}"
        if not key.isdigit():
            raise MachineFileError(f"{where}: the key is not an M code number; expected {form}")
        if not isinstance(item, dict) or "means" not in item or not set(item) <= {"means", "source"}:
            raise MachineFileError(f"{where}: expected {form}, got {item!r}")
        means = item["means"]
        if not isinstance(means, list):
            raise MachineFileError(f"{where}: means must be a list of M code numbers; expected {form}")
        problem = alias_problem(int(key), means)
        if problem is not None:
            raise MachineFileError(f"{where}: {problem}")
        if "source" in item:
            provenance[f"{M_CODES_SECTION}.{key}"] = str(item["source"])
        out[key] = list(means)
    return out


def _check_complete(path: Path, text: str, values: dict[str, Any]) -> None:
    for section, keys in SCHEMA.items():
        if "*" in section or section in OPTIONAL_SECTIONS:
            continue
        node: Any = values
        for part in section.split("."):
            node = node.get(part) if isinstance(node, dict) else None
        if node is None:
            raise MachineFileError(f"{path}: missing section [{section}] with keys {sorted(keys)}")
        missing = sorted(keys - set(node) - OPTIONAL_KEYS.get(section, set()))
        if missing:
            raise MachineFileError(
                f"{path}:{_line_of(text, section, None)}: section [{section}] is missing {missing}"
            )


def _check_relations(path: Path, text: str, values: dict[str, Any]) -> None:
    """Checks between keys: the servo loop periods, the position loop gains, the drives' internal step, the chatter
    mode."""
    servo = values.get("servo", {})
    tp, tv = servo.get("position_loop_period_ms"), servo.get("velocity_loop_period_ms")
    if tp is not None and tv is not None:
        ratio = round(tp / tv)
        if ratio < 1 or abs(ratio * tv - tp) > 1e-9 * tp:
            raise MachineFileError(
                f"{path}:{_line_of(text, 'servo', 'position_loop_period_ms')}: [servo] position_loop_period_ms = "
                f"{tp!r} must be a whole multiple (1, 2, ...) of velocity_loop_period_ms = {tv!r}")
    _check_position_gains(path, text, values)
    from fmus_src.servo.step_cap import stribeck_step_cap
    from fmus_src.servo.friction import StribeckParameters

    for a in AXES:
        axis = values.get("axis", {}).get(a, {})
        friction = axis.get("friction", {})
        pos, neg = friction.get("positive"), friction.get("negative")
        if "mass_kg" not in axis or pos is None or neg is None:
            continue
        branches = {f"{k}_{d}": np.array([float(table[key])]) for d, table in (("pos", pos), ("neg", neg))
                    for k, key in (("coulomb", "coulomb_N"), ("static", "static_N"),
                                   ("stribeck_velocity", "stribeck_velocity_m_per_s"), ("viscous", "viscous_Ns_per_m"))}
        with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
            cap = float(stribeck_step_cap(StribeckParameters(**branches), np.array([float(axis["mass_kg"])]))[0])
        if not cap >= MIN_DRIVE_STEP_S:
            raise MachineFileError(
                f"{path}:{_line_of(text, f'axis.{a}', 'mass_kg')}: [axis.{a}] mass_kg = {axis['mass_kg']!r} with the "
                f"Stribeck friction of [axis.{a}.friction.*] (static - coulomb over stribeck_velocity) needs drive "
                f"substeps of {cap:.3g} s; expected a moving mass and friction that allow at least "
                f"{MIN_DRIVE_STEP_S:g} s (a larger mass_kg or stribeck_velocity_m_per_s)")
    _check_machine_zero(path, text, values)
    _check_strokes(path, text, values)
    effects = values.get("cutting", {}).get("effects", {})
    if effects.get("chatter_frequency_Hz", 0.0) > 0.0 and not effects.get("chatter_stiffness_N_per_um", 0.0) > 0.0:
        raise MachineFileError(
            f"{path}:{_line_of(text, 'cutting.effects', 'chatter_stiffness_N_per_um')}: [cutting.effects] "
            f"chatter_frequency_Hz = {effects['chatter_frequency_Hz']!r} needs chatter_stiffness_N_per_um > 0 "
            f"(the modal stiffness of the chatter mode), got {effects.get('chatter_stiffness_N_per_um', 0.0)!r}")


def _check_position_gains(path: Path, text: str, values: dict[str, Any]) -> None:
    """Each axis's position loop gain Kv = ``position_gain_per_s`` x ``position_scale`` (1/s) is at least
    :data:`~fmus_src.nck.params.MIN_POSITION_GAIN`: the NC kernel's in-position model before rapids
    (``[nck] in_position_before_rapid``) divides by the smallest Kv, and its wait grows as 1 / Kv. Each key on
    its own is checked > 0 by :data:`VALUE_RULES`; this catches a product that is too small or underflows."""
    for a in AXES:
        axis = values.get("axis", {}).get(a, {})
        gain, scale = axis.get("position_gain_per_s"), axis.get("position_scale")
        if gain is None or scale is None:
            continue
        kv = float(gain) * float(scale)
        if not (math.isfinite(kv) and kv >= MIN_POSITION_GAIN):
            raise MachineFileError(
                f"{path}:{_line_of(text, f'axis.{a}', 'position_gain_per_s')}: [axis.{a}] position_gain_per_s x "
                f"position_scale = {gain!r} x {scale!r} = {kv:.6g} 1/s is the axis's position loop gain Kv (of the "
                f"servo and of the in-position check before rapids); expected a finite Kv of at least "
                f"{MIN_POSITION_GAIN:g} 1/s (FANUC No. 1825's smallest setting)")


def _check_machine_zero(path: Path, text: str, values: dict[str, Any]) -> None:
    """``machine_zero_{x,y,z}_mm``: all three or none."""
    nck = values.get("nck", {})
    given = [k for k in MACHINE_ZERO_KEYS if k in nck]
    if given and len(given) < len(MACHINE_ZERO_KEYS):
        missing = [k for k in MACHINE_ZERO_KEYS if k not in nck]
        raise MachineFileError(
            f"{path}:{_line_of(text, 'nck', given[0])}: [nck] {given[0]} without {', '.join(missing)}; expected "
            "all three machine_zero_{x,y,z}_mm (where machine zero sits in the twin's axis frame) or none (machine "
            "coordinates = the axis frame)")


def _reference_default(nck: dict[str, Any]) -> float | None:
    """The reference position of a file that leaves it out (mm): 0 (machine zero, FANUC No. 1240 = 0) when the
    file places machine zero, else None (the NC kernel's default, :data:`fmus_src.nck.settings.DEFAULT_REFERENCE`)."""
    return 0.0 if all(k in nck for k in MACHINE_ZERO_KEYS) else None


def _check_strokes(path: Path, text: str, values: dict[str, Any]) -> None:
    """Stroke limits: both or none per axis, minimum < maximum, every reference position (G28/G30) inside."""
    nck = values.get("nck", {})
    for a in AXES:
        axis = values.get("axis", {}).get(a, {})
        given = [k for k in STROKE_KEYS if k in axis]
        if not given:
            continue
        where = f"{path}:{_line_of(text, f'axis.{a}', given[0])}: [axis.{a}]"
        if len(given) == 1:
            missing = next(k for k in STROKE_KEYS if k not in axis)
            raise MachineFileError(f"{where} {given[0]} without {missing}; expected both stored stroke limits "
                                   "(FANUC No. 1321 and No. 1320) or neither (no stroke check)")
        lo, hi = float(axis["stroke_min_mm"]), float(axis["stroke_max_mm"])
        if not lo < hi:
            raise MachineFileError(f"{where} stroke_min_mm = {lo!r} must be less than stroke_max_mm = {hi!r}")
        for n in ("", "2", "3", "4"):
            key = f"reference{n}_{a}_mm"
            ref = nck.get(key, nck.get(f"reference_{a}_mm", _reference_default(nck)))
            if ref is not None and not lo <= float(ref) <= hi:
                raise MachineFileError(
                    f"{path}:{_line_of(text, 'nck', key if key in nck else f'reference_{a}_mm')}: [nck] {key} = "
                    f"{float(ref)!r} is outside the stroke limits of [axis.{a}] [{lo!r}, {hi!r}] mm; expected a "
                    "reference position inside the travel (a reference return there would be an overtravel)")


def frame_parameters(machine: Machine) -> dict[str, float]:
    """NC kernel parameters (m) of the machine coordinate frame of a machine file.

    With ``[nck] machine_zero_{x,y,z}_mm``: ``machine_zero_<a>``, the default work offsets G54..G59 =
    -machine zero (their work coordinates are the axis frame: recordings, stock and ``case.toml`` keep those),
    and 0 (machine zero, FANUC No. 1240 = 0) for a reference position the file leaves out. Without them: nothing
    (the NC kernel's defaults: machine coordinates are the axis frame).
    """
    zero = machine.machine_zero()
    if zero is None:
        return {}
    nck = machine.values.get("nck", {})
    params: dict[str, float] = {}
    for i, a in enumerate(AXES):
        params[f"machine_zero_{a}"] = zero[i]
        for g in range(54, 60):
            params[f"g{g}_{a}"] = -zero[i]
        if f"reference_{a}_mm" not in nck:
            params[f"reference_{a}"] = 0.0
    return params


def resolve_machine_path(name_or_path: str | Path, relative_to: Path | None = None) -> Path:
    """Find a machine file: a name shipped in ``models/machines`` or a path.

    Parameters
    ----------
    name_or_path : str or Path
        ``"default"`` (a shipped set) or a path to a ``.toml`` file.
    relative_to : Path, optional
        Folder that relative paths are taken from (e.g. a case folder).
    """
    text = str(name_or_path)
    if "/" not in text and "\\" not in text and not text.endswith(".toml"):
        candidate = MACHINES_DIR / f"{text}.toml"
        if candidate.is_file():
            return candidate
        shipped = sorted(p.stem for p in MACHINES_DIR.glob("*.toml"))
        raise MachineFileError(f"no machine parameter set named {text!r}; shipped sets: {shipped}")
    path = Path(text)
    if not path.is_absolute() and relative_to is not None:
        path = relative_to / path
    if not path.is_file():
        raise MachineFileError(f"{path}: machine parameter file not found")
    return path


def load_machine(name_or_path: str | Path = "default", relative_to: Path | None = None) -> Machine:
    """Load and validate a machine parameter set.

    Parameters
    ----------
    name_or_path : str or Path
        Shipped set name (``"default"``) or path to a TOML file.
    relative_to : Path, optional
        Folder for relative paths.

    Returns
    -------
    Machine

    Raises
    ------
    MachineFileError
        File missing, not TOML, unknown key, missing key, non-numeric value.
    """
    path = resolve_machine_path(name_or_path, relative_to)
    try:
        text = path.read_text(encoding="utf-8-sig")  # a BOM (Windows editors) is not TOML: dropped
    except UnicodeDecodeError as exc:
        raise MachineFileError(f"{path}: not a UTF-8 text file (byte offset {exc.start}); expected a TOML machine file") from None
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise MachineFileError(f"{path}: not valid TOML: {exc}") from None
    except RecursionError:  # tomllib parses nested arrays and tables recursively
        raise MachineFileError(f"{path}: arrays or tables nested too deeply to read; expected a TOML machine file") from None
    provenance: dict[str, str] = {}
    values = _flatten(path, text, raw, "", provenance)
    _check_complete(path, text, values)
    _check_relations(path, text, values)
    return Machine(path=path, values=values, provenance=provenance)


def _toml_value(value: Any) -> str:
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    return repr(float(value)) if isinstance(value, float) else str(value)


def machine_to_toml(machine: Machine, extra_provenance: dict[str, str] | None = None) -> str:
    """Render a machine as TOML in the shipped format (values with provenance)."""
    sources = {**machine.provenance, **(extra_provenance or {})}
    lines: list[str] = []

    def emit(node: dict[str, Any], section: str) -> None:
        plain = {k: v for k, v in node.items() if not isinstance(v, dict)}
        if plain:
            if section:
                lines.append(f"[{section}]")
            for key, value in plain.items():
                dotted = f"{section}.{key}" if section else key
                if isinstance(value, list):  # [nck.m_codes]
                    source = f", source = {_toml_value(sources[dotted])}" if dotted in sources else ""
                    lines.append(f"{key} = {{ means = [{', '.join(str(m) for m in value)}]{source} }}")
                elif dotted in sources:
                    lines.append(f"{key} = {{ value = {_toml_value(value)}, source = {_toml_value(sources[dotted])} }}")
                else:
                    lines.append(f"{key} = {_toml_value(value)}")
            lines.append("")
        for key, value in node.items():
            if isinstance(value, dict):
                emit(value, f"{section}.{key}" if section else key)

    emit(machine.values, "")
    return "\n".join(lines)
