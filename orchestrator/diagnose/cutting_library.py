"""The cutting-effect catalogue: spec names and units, component parameters, machine keys, candidate columns.

Every cutting effect of ``shared/spec/diagnosis.md`` maps onto parameters of
the twin's cutting component (:class:`fmus_src.cutting.CuttingLoad`,
``[cutting.effects]`` in the machine file), all 0 (off) in the paper's model:

==================  ==========================================  =================================
effect              spec parameters                             component parameters (SI)
==================  ==========================================  =================================
``runout``          ``eccentricity_um``, ``phase_deg``          ``runout_eccentricity``, ``runout_phase``
``helix_angle``     ``helix_deg``                               ``helix_angle``
``edge_force``      ``kte_N_per_mm``, ``kre_N_per_mm``          ``edge_force_tangential``, ``edge_force_radial``
``tool_deflection`` ``stiffness_N_per_um``                      ``tool_stiffness``
``tool_wear``       ``rate_percent_per_min``                    ``wear_rate``
``spindle_droop``   ``rpm_per_Nm``                              ``spindle_droop``
``chatter``         ``frequency_Hz``                            ``chatter_frequency``
==================  ==========================================  =================================

Columns for the selection (:mod:`.select`) are replay differences per unit
of a *linear* parameter (a batch member with the parameter at ``unit``
minus the baseline): runout as its two components ``rho cos(lambda)``,
``rho sin(lambda)``; the helix as one coefficient per trial angle (the
angle is refitted afterwards); the tool deflection as a compliance (the
force falls by ``Kr d c`` per unit compliance ``c``). The spindle droop
acts on ``spindle_rpm`` only: ``-T`` (the model's cutting torque) per
rpm/N.m. Chatter is found in the force spectrum (:mod:`.cutting_locate`),
not by regression: a regenerative vibration cannot be replayed sample by
sample.
"""
from __future__ import annotations

import math
from typing import Mapping

from .library import Column, Variant

#: Cutting effect -> its parameters (spec names), in the spec's order.
CUTTING_EFFECT_PARAMETERS: dict[str, tuple[str, ...]] = {
    "runout": ("eccentricity_um", "phase_deg"),
    "helix_angle": ("helix_deg",),
    "edge_force": ("kte_N_per_mm", "kre_N_per_mm"),
    "tool_deflection": ("stiffness_N_per_um",),
    "tool_wear": ("rate_percent_per_min",),
    "spindle_droop": ("rpm_per_Nm",),
    "chatter": ("frequency_Hz",),
}

#: Channels on which each cutting effect shows.
CUTTING_CHANNELS: dict[str, tuple[str, ...]] = {
    "runout": ("fx_N", "fy_N", "fc_N"), "helix_angle": ("fx_N", "fy_N", "fc_N"),
    "edge_force": ("fx_N", "fy_N", "fc_N"), "tool_deflection": ("fx_N", "fy_N", "fc_N"),
    "tool_wear": ("fx_N", "fy_N", "fc_N"), "spindle_droop": ("spindle_rpm",), "chatter": ("fx_N", "fy_N", "fc_N"),
}

#: ``where.event`` of each cutting effect.
CUTTING_EVENTS: dict[str, str] = {
    "runout": "cutting: force at the spindle frequency", "helix_angle": "cutting: tooth entry and exit",
    "edge_force": "cutting: every engaged tooth", "tool_deflection": "cutting: deep cuts",
    "tool_wear": "cutting: growing with cutting time", "spindle_droop": "cutting: spindle under load",
    "chatter": "cutting: vibration off the tooth-passing harmonics",
}

#: Helix angles (deg) of the selection's trial columns.
HELIX_GRID_DEG = (15.0, 30.0, 45.0)

#: Replay perturbation of each linear column (spec units).
UNITS: dict[str, float] = {
    "runout.a_um": 4.0, "runout.b_um": 4.0, "edge_force.kte_N_per_mm": 5.0, "edge_force.kre_N_per_mm": 5.0,
    "tool_deflection.compliance_um_per_N": 0.02, "tool_wear.rate_percent_per_min": 10.0,
}


def _col(effect: str, parameter: str, unit: float, **fixed: float) -> Column:
    tag = ",".join(f"{k}={v:g}" for k, v in fixed.items())
    return Column(f"{effect}.{parameter}" + (f"@{tag}" if tag else ""), effect, parameter, tuple(fixed.items()),
                  "dynamic", unit)


def cutting_variants(flutes: int, droop: bool) -> list[Variant]:
    """Candidate variants of the cutting effects.

    Parameters
    ----------
    flutes : int
        With 2 flutes runout changes the chips by ``+-2 rho cos(lambda)`` only: one column.
    droop : bool
        Whether ``spindle_rpm`` is recorded (droop candidate).
    """
    a = _col("runout", "a_um", UNITS["runout.a_um"])
    b = _col("runout", "b_um", UNITS["runout.b_um"])
    out = [Variant("runout", (a,) if flutes == 2 else (a, b))]
    for deg in HELIX_GRID_DEG:
        out.append(Variant("helix_angle", (_col("helix_angle", "scale", 1.0, helix_deg=deg),), {"helix_deg": deg}))
    kte = _col("edge_force", "kte_N_per_mm", UNITS["edge_force.kte_N_per_mm"])
    kre = _col("edge_force", "kre_N_per_mm", UNITS["edge_force.kre_N_per_mm"])
    out += [Variant("edge_force", (kte,)), Variant("edge_force", (kte, kre))]
    out.append(Variant("tool_deflection", (_col("tool_deflection", "compliance_um_per_N",
                                                UNITS["tool_deflection.compliance_um_per_N"]),)))
    out.append(Variant("tool_wear", (_col("tool_wear", "rate_percent_per_min",
                                          UNITS["tool_wear.rate_percent_per_min"]),)))
    if droop:
        out.append(Variant("spindle_droop", (Column("spindle_droop.rpm_per_Nm", "spindle_droop", "rpm_per_Nm", (),
                                                    "kinematic", 1.0),)))
    return out


def component_values(effects: Mapping[str, Mapping[str, float]]) -> dict[str, float]:
    """Cutting-component parameter overrides (SI) for effects in spec units (plus ``kt``/``ke`` when given).

    ``effects`` may hold the pseudo-effect ``"coefficients"`` with ``kt_N_per_m2`` and ``ke``
    (the refitted cutting coefficients).
    """
    out: dict[str, float] = {}
    for effect, p in effects.items():
        if effect == "coefficients":
            if "kt_N_per_m2" in p:
                out["kt"] = float(p["kt_N_per_m2"])
            if "ke" in p:
                out["ke"] = float(p["ke"])
        elif effect == "runout":
            out["runout_eccentricity"] = max(float(p.get("eccentricity_um", 0.0)), 0.0) * 1e-6
            out["runout_phase"] = math.radians(float(p.get("phase_deg", 0.0)))
        elif effect == "helix_angle":
            out["helix_angle"] = math.radians(float(p.get("helix_deg", 0.0)))
        elif effect == "edge_force":
            out["edge_force_tangential"] = max(float(p.get("kte_N_per_mm", 0.0)), 0.0) * 1e3
            out["edge_force_radial"] = max(float(p.get("kre_N_per_mm", 0.0)), 0.0) * 1e3
        elif effect == "tool_deflection":
            k = float(p.get("stiffness_N_per_um", 0.0))
            out["tool_stiffness"] = k * 1e6 if k > 0 else 0.0
        elif effect == "tool_wear":
            out["wear_rate"] = max(float(p.get("rate_percent_per_min", 0.0)), 0.0) / 100.0 / 60.0
        elif effect in ("spindle_droop", "chatter"):
            continue  # droop acts on spindle_rpm (fed as recorded); chatter is found in the spectrum
        else:
            raise KeyError(f"unknown cutting effect {effect!r}; expected one of {sorted(CUTTING_EFFECT_PARAMETERS)}")
    return out


def machine_keys(effect: str, params: Mapping[str, float]) -> dict[str, float]:
    """Keys of ``[cutting.effects]`` (units in the names) for a found cutting effect."""
    p = dict(params)
    table = {
        "runout": {"eccentricity_um": p.get("eccentricity_um", 0.0), "phase_deg": p.get("phase_deg", 0.0)},
        "helix_angle": {"helix_deg": p.get("helix_deg", 0.0)},
        "edge_force": {"kte_N_per_mm": p.get("kte_N_per_mm", 0.0), "kre_N_per_mm": p.get("kre_N_per_mm", 0.0)},
        "tool_deflection": {"tool_stiffness_N_per_um": p.get("stiffness_N_per_um", 0.0)},
        "tool_wear": {"wear_rate_percent_per_min": p.get("rate_percent_per_min", 0.0)},
        "spindle_droop": {"spindle_droop_rpm_per_Nm": p.get("rpm_per_Nm", 0.0)},
        # the twin's tool mode: its natural frequency when refitted (else the chatter frequency), damping, stiffness
        "chatter": {"chatter_frequency_Hz": p.get("natural_frequency_Hz", p.get("frequency_Hz", 0.0)),
                    **({"chatter_damping_ratio": p["damping_ratio"]} if "damping_ratio" in p else {}),
                    **({"chatter_stiffness_N_per_um": p["stiffness_N_per_um"]} if "stiffness_N_per_um" in p else {})},
    }
    return table[effect]
