"""The effect catalogue: spec names and units, component parameters, candidate terms for the regression.

Every drive/controller effect of ``shared/spec/diagnosis.md`` maps onto
parameters of :class:`fmus_src.servo.DriveAxis` / :class:`fmus_src.servo.MCU`
(:func:`component_values`). For the sparse regression each effect offers one
or more *variants*: a set of linear coefficients (``linear``) with the
nonlinear parameters fixed on a small grid (``fixed``, e.g. a ripple period).

Two kinds of columns:

``dynamic``
    The effect changes the loop (gravity, friction, mass, ripple, reversal
    friction, feed-forward, delay): its column is the difference of a
    batched replay with the parameter perturbed by ``unit`` from the baseline.
``kinematic``
    The effect lives between motor and table (backlash, compliance, pitch,
    drift): its column follows exactly from the baseline's motor position
    and force, no replay needed.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

#: Effect -> its parameters (spec names, units in the names), in the spec's order.
EFFECT_PARAMETERS: dict[str, tuple[str, ...]] = {
    "gravity": ("force_N", "spring_N_per_mm"),
    "backlash": ("width_um",),
    "reversal_friction": ("peak_N", "decay_mm"),
    "friction_mismatch": ("coulomb_N", "viscous_Ns_per_m"),
    "inertia_mismatch": ("mass_kg",),
    "screw_compliance": ("stiffness_N_per_um",),
    "pitch_error": ("slope_um_per_m", "amplitude_um", "period_mm"),
    "thermal_drift": ("rate_um_per_min",),
    "torque_ripple": ("amplitude_N", "period_mm"),
    "velocity_feedforward": ("gain",),
    "servo_delay": ("delay_ms",),
    "current_saturation": ("limit_A",),
}

#: Channels on which each effect shows (FE = following error ``{a}_fe_um``, TC = ``{a}_tcmd_A``).
EFFECT_CHANNELS: dict[str, tuple[str, ...]] = {
    "gravity": ("tcmd", "fe"), "backlash": ("fe",), "reversal_friction": ("tcmd", "fe"),
    "friction_mismatch": ("tcmd", "fe"), "inertia_mismatch": ("tcmd", "fe"), "screw_compliance": ("fe",),
    "pitch_error": ("fe",), "thermal_drift": ("fe",), "torque_ripple": ("tcmd", "fe"),
    "velocity_feedforward": ("fe", "tcmd"), "servo_delay": ("fe", "tcmd"), "current_saturation": ("tcmd", "fe"),
}

#: Events at which an effect's signature concentrates (diagnosis.json ``where.event``).
EFFECT_EVENTS: dict[str, str | None] = {
    "gravity": "up- and down-strokes", "backlash": "reversals", "reversal_friction": "reversals",
    "friction_mismatch": "constant velocity", "inertia_mismatch": "accelerations", "screw_compliance": "accelerations",
    "pitch_error": None, "thermal_drift": None, "torque_ripple": "constant velocity",
    "velocity_feedforward": "constant velocity", "servo_delay": "accelerations", "current_saturation": "accelerations",
}


@dataclass(frozen=True)
class Column:
    """One regression column: a linear coefficient of an effect at fixed nonlinear parameters.

    Attributes
    ----------
    key : str
        Unique label (``"torque_ripple.amplitude_N@period_mm=6"``).
    effect : str
    parameter : str
        The linear parameter (spec name).
    fixed : tuple of (str, float)
        Nonlinear parameters held at these values.
    kind : {"dynamic", "kinematic", "artefact"}
    unit : float
        Perturbation (spec units) of a dynamic column.
    """

    key: str
    effect: str
    parameter: str
    fixed: tuple[tuple[str, float], ...] = ()
    kind: str = "dynamic"
    unit: float = 1.0


@dataclass(frozen=True)
class Variant:
    """A candidate model of one effect: some columns fitted together."""

    effect: str
    columns: tuple[Column, ...]
    fixed: dict = field(default_factory=dict, hash=False, compare=False)

    @property
    def label(self) -> str:
        fixed = ", ".join(f"{k}={v:g}" for k, v in self.fixed.items())
        names = "+".join(c.parameter for c in self.columns)
        return f"{self.effect}({names}{'; ' + fixed if fixed else ''})"


def _col(effect: str, parameter: str, kind: str, unit: float = 1.0, **fixed: float) -> Column:
    tag = ",".join(f"{k}={v:g}" for k, v in fixed.items())
    return Column(f"{effect}.{parameter}" + (f"@{tag}" if tag else ""), effect, parameter,
                  tuple(fixed.items()), kind, unit)


#: Not an effect: a current channel logged with a scale error (spec: a recording artefact, estimated and
#: corrected before the effects, reported under ``alignment``). Offered to the selection next to the
#: effects, so that it is taken only when it explains the current better than any physics does.
CHANNEL_SCALE = "channel_scale"


def channel_scale_variant(axis: str) -> Variant:
    """The scale error of ``{axis}_tcmd_A``: its column is the replayed current (coefficient: scale - 1)."""
    return Variant(CHANNEL_SCALE, (Column(f"{axis}_tcmd_A scale", CHANNEL_SCALE, "scale_minus_1", (), "artefact"),))


def candidate_variants(axis: str, lead_mm: float, vertical: bool) -> list[Variant]:
    """The candidate variants of one axis.

    Parameters
    ----------
    axis : str
    lead_mm : float
        Ball-screw lead: ripple and pitch periods are searched at ``lead / n``.
    vertical : bool
        Gravity is a candidate only on a vertical axis.
    """
    out: list[Variant] = []
    if vertical:
        force = _col("gravity", "force_N", "dynamic", 100.0)
        spring = _col("gravity", "spring_N_per_mm", "dynamic", 2.0)
        out += [Variant("gravity", (force,)), Variant("gravity", (force, spring))]
    for decay in (0.02, 0.1, 0.5):
        out.append(Variant("reversal_friction", (_col("reversal_friction", "peak_N", "dynamic", 100.0,
                                                      decay_mm=decay),), {"decay_mm": decay}))
    coulomb = _col("friction_mismatch", "coulomb_N", "dynamic", 50.0)
    viscous = _col("friction_mismatch", "viscous_Ns_per_m", "dynamic", 1000.0)
    out += [Variant("friction_mismatch", (coulomb,)), Variant("friction_mismatch", (viscous,)),
            Variant("friction_mismatch", (coulomb, viscous))]
    out.append(Variant("inertia_mismatch", (_col("inertia_mismatch", "mass_kg", "dynamic", 50.0),)))
    for n in (1, 2, 3, 4, 6):
        period = round(lead_mm / n, 6)
        out.append(Variant("torque_ripple", (_col("torque_ripple", "amplitude_N", "dynamic", 30.0,
                                                  period_mm=period),), {"period_mm": period}))
    out.append(Variant("velocity_feedforward", (_col("velocity_feedforward", "gain", "dynamic", 0.1),)))
    out.append(Variant("servo_delay", (_col("servo_delay", "delay_ms", "dynamic", 0.25),)))
    # a delay's effect on the loop is far from linear over a few ticks (the answer to the 200 Hz tooth
    # load turns by 72 degrees per ms): a second column linearised over 1 ms (four velocity ticks)
    out.append(Variant("servo_delay", (Column("servo_delay.delay_ms@over=1ms", "servo_delay", "delay_ms", (),
                                              "dynamic", 1.0),)))
    out.append(Variant("backlash", (_col("backlash", "width_um", "kinematic"),)))
    out.append(Variant("screw_compliance", (_col("screw_compliance", "compliance_um_per_N", "kinematic"),)))
    slope = _col("pitch_error", "slope_um_per_m", "kinematic")
    out.append(Variant("pitch_error", (slope,), {"amplitude_um": 0.0, "period_mm": 0.0}))
    for n in (1, 2, 4):
        period = round(lead_mm / n, 6)
        amp = _col("pitch_error", "amplitude_um", "kinematic", period_mm=period)
        out.append(Variant("pitch_error", (amp,), {"slope_um_per_m": 0.0, "period_mm": period}))
        out.append(Variant("pitch_error", (slope, amp), {"period_mm": period}))
    out.append(Variant("thermal_drift", (_col("thermal_drift", "rate_um_per_min", "kinematic"),)))
    return out


def dynamic_columns(variants: list[Variant]) -> list[Column]:
    """The distinct dynamic columns of ``variants`` (one replay member each)."""
    seen: dict[str, Column] = {}
    for v in variants:
        for c in v.columns:
            if c.kind == "dynamic":
                seen.setdefault(c.key, c)
    return list(seen.values())


def component_values(axis: str, effects: Mapping[str, Mapping[str, np.ndarray | float]],
                     base_drive: Mapping[str, float], base_mcu: Mapping[str, float]
                     ) -> tuple[dict[str, np.ndarray | float], dict[str, np.ndarray | float]]:
    """DriveAxis and MCU parameter overrides of one axis for effects in spec units.

    Parameters
    ----------
    axis : str
    effects : mapping effect -> {parameter (spec name): value or (B,) array}
        Mismatch effects are differences to ``base_*``; the others absolute.
    base_drive, base_mcu : mapping
        The baseline DriveAxis parameters of the axis and the MCU parameters.

    Returns
    -------
    drive, mcu : dict
        Overrides (``{"gravity_force": ...}``, ``{"z_servo_delay": ...}``).
    """
    drive: dict[str, np.ndarray | float] = {}
    mcu: dict[str, np.ndarray | float] = {}
    for effect, p in effects.items():
        g = lambda name, default=0.0: p.get(name, default)  # noqa: E731
        if effect == "gravity":
            drive["gravity_force"] = g("force_N")
            drive["gravity_spring"] = np.asarray(g("spring_N_per_mm")) * 1e3
        elif effect == "backlash":
            drive["backlash_width"] = np.asarray(g("width_um")) * 1e-6
        elif effect == "reversal_friction":
            drive["reversal_friction_peak"] = g("peak_N")
            drive["reversal_friction_decay"] = np.asarray(g("decay_mm")) * 1e-3
        elif effect == "friction_mismatch":
            for d in ("positive", "negative"):
                dc = np.asarray(g("coulomb_N"))
                drive[f"coulomb_{d}"] = np.maximum(base_drive[f"coulomb_{d}"] + dc, 0.0)
                drive[f"static_{d}"] = np.maximum(base_drive[f"static_{d}"] + dc, 0.0)
                drive[f"viscous_{d}"] = np.maximum(base_drive[f"viscous_{d}"] + np.asarray(g("viscous_Ns_per_m")), 0.0)
        elif effect == "inertia_mismatch":
            drive["mass"] = base_drive["mass"] + np.asarray(g("mass_kg"))
            mcu[f"{axis}_mass"] = base_mcu[f"{axis}_mass"] + np.asarray(g("mass_kg"))
        elif effect == "screw_compliance":
            k = np.asarray(g("stiffness_N_per_um"), dtype=float)
            drive["screw_stiffness"] = np.where(k > 0.0, k, 0.0) * 1e6
        elif effect == "pitch_error":
            drive["pitch_slope"] = np.asarray(g("slope_um_per_m")) * 1e-6
            drive["pitch_amplitude"] = np.asarray(g("amplitude_um")) * 1e-6
            drive["pitch_period"] = np.asarray(g("period_mm")) * 1e-3
        elif effect == "thermal_drift":
            drive["thermal_drift_rate"] = np.asarray(g("rate_um_per_min")) * 1e-6 / 60.0
        elif effect == "torque_ripple":
            drive["ripple_amplitude"] = g("amplitude_N")
            drive["ripple_period"] = np.asarray(g("period_mm")) * 1e-3
        elif effect == "velocity_feedforward":
            mcu[f"{axis}_velocity_feedforward"] = base_mcu[f"{axis}_velocity_feedforward"] + np.asarray(g("gain"))
        elif effect == "servo_delay":
            mcu[f"{axis}_servo_delay"] = np.maximum(np.asarray(g("delay_ms")) * 1e-3, 0.0)
        elif effect == "current_saturation":
            mcu[f"{axis}_peak_current"] = g("limit_A", base_mcu[f"{axis}_peak_current"])
        else:
            raise KeyError(f"unknown effect {effect!r}; expected one of {sorted(EFFECT_PARAMETERS)}")
    return drive, mcu


def machine_keys(effect: str, params: Mapping[str, float]) -> dict[str, float]:
    """Keys of ``[axis.<a>.effects]`` (units in the names) for a found effect (absolute effects only)."""
    p = dict(params)
    table = {
        "gravity": {"gravity_force_N": p.get("force_N", 0.0), "gravity_spring_N_per_mm": p.get("spring_N_per_mm", 0.0)},
        "backlash": {"backlash_width_um": p.get("width_um", 0.0)},
        "reversal_friction": {"reversal_friction_peak_N": p.get("peak_N", 0.0),
                              "reversal_friction_decay_mm": p.get("decay_mm", 0.0)},
        "screw_compliance": {"screw_stiffness_N_per_um": p.get("stiffness_N_per_um", 0.0)},
        "pitch_error": {"pitch_slope_um_per_m": p.get("slope_um_per_m", 0.0),
                        "pitch_amplitude_um": p.get("amplitude_um", 0.0), "pitch_period_mm": p.get("period_mm", 0.0)},
        "thermal_drift": {"thermal_drift_rate_um_per_min": p.get("rate_um_per_min", 0.0)},
        "torque_ripple": {"ripple_amplitude_N": p.get("amplitude_N", 0.0), "ripple_period_mm": p.get("period_mm", 0.0)},
        "servo_delay": {"servo_delay_ms": p.get("delay_ms", 0.0)},
    }
    return table.get(effect, {})
