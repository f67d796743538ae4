"""Parameters and state of the cutting-effect terms of :class:`.component.CuttingLoad` (issue 8).

Every term is off at 0, the paper's model. The physics is in :mod:`.effects`
(pure functions) and :mod:`.chip` (scalar kernels); this module checks the
component parameters, lays out the helix bands and holds the state that the
terms carry from step to step (cutting time, previous torque, tool vibration
and its history over one tooth pitch).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import CncTwinError
from ..jit import njit
from .effects import runout_radius_offsets

#: Most surfaces a tooth may cut (the ones left by the last MAX_PASSES teeth: multiple regeneration); with
#: a tool mode every tooth considers this many. One revolution of a 3-flute tool plus the two teeth that jump
#: out of the cut at a chatter limit cycle: in the truth's chatter case (1150 Hz, 3 %, 30 N/um, 2 mm slot,
#: 3 flutes) the teeth cut surfaces left 1..5 periods back (5: 3 % of the cutting instants), never 6 or more,
#: and the limit cycle is 57.6 N with 5, 6 or 9 surfaces (59.4 N with 4, 68.3 N with 3). The independent
#: truth (``orchestrator.diagnose.truth_cutting.CHATTER_PASSES``) remembers the same number.
MAX_PASSES = 5
#: Finest history spacing: ``pitch / HISTORY_PER_PITCH`` of spindle angle.
HISTORY_PER_PITCH = 1024
#: Ring-buffer length of the regenerative history (entries per member): spans MAX_PASSES + 1 pitches.
HISTORY_CAPACITY = HISTORY_PER_PITCH * (MAX_PASSES + 1)
#: Least substeps per period of the tool mode when chatter is on (exact mode step, force held per substep).
CHATTER_SUBSTEPS_PER_PERIOD = 32
#: Most helix bands along the axial depth (beyond it the bands get taller than the angular resolution).
MAX_BANDS = 256

#: Component parameter names of the effect terms, in the order of :attr:`EffectParameters.packed`.
PARAMETER_NAMES = (
    "runout_eccentricity", "runout_phase", "helix_angle", "edge_force_tangential", "edge_force_radial",
    "tool_stiffness", "wear_rate", "spindle_droop", "chatter_frequency", "chatter_damping", "chatter_stiffness",
)


class EffectParameterError(CncTwinError):
    """An effect parameter of the cutting load is out of range."""


@dataclass(frozen=True)
class EffectParameters:
    """The effect terms of one batch, arrays of shape (B,), SI.

    Attributes
    ----------
    eccentricity : ndarray
        Cutter runout ``rho`` [m].
    phase : ndarray
        Angle of the eccentricity from tooth 0, clockwise [rad].
    tan_helix : ndarray
        ``tan`` of the helix angle [1].
    kte, kre : ndarray
        Edge force coefficients per unit axial depth [N/m].
    stiffness : ndarray
        Static tool stiffness [N/m] (0 = rigid).
    wear_rate : ndarray
        Growth of the cutting coefficients per second of cutting [1/s].
    droop : ndarray
        Spindle speed drop per cutting torque [(rad/s)/(N.m)].
    chatter_wn : ndarray
        Natural angular frequency of the tool mode [rad/s] (0 = off).
    chatter_zeta : ndarray
        Damping ratio of the tool mode [1].
    chatter_k : ndarray
        Modal stiffness of the tool mode [N/m].
    """

    eccentricity: np.ndarray
    phase: np.ndarray
    tan_helix: np.ndarray
    kte: np.ndarray
    kre: np.ndarray
    stiffness: np.ndarray
    wear_rate: np.ndarray
    droop: np.ndarray
    chatter_wn: np.ndarray
    chatter_zeta: np.ndarray
    chatter_k: np.ndarray

    @classmethod
    def from_values(cls, values: dict, component: str,
                    error: type[CncTwinError] = EffectParameterError) -> "EffectParameters":
        """Check and convert the component's effect parameters.

        Parameters
        ----------
        values : dict
            The component's values by name (arrays of shape (B,)).
        component : str
            Instance name, for messages.
        error : type
            Error raised (the component's own error type).

        Raises
        ------
        EffectParameterError
            Or ``error``: naming ``component.parameter``, the member and the expected range.
        """
        v = {n: np.asarray(values[n], dtype=np.float64) for n in PARAMETER_NAMES}
        checks = (
            ("runout_eccentricity", lambda a: a >= 0, "a length >= 0 in m"),
            ("runout_phase", lambda a: np.ones_like(a, dtype=bool), "a finite angle in rad"),
            ("helix_angle", lambda a: np.abs(a) < math.radians(80.0), "an angle in rad with |helix| < 80 deg"),
            ("edge_force_tangential", lambda a: a >= 0, "a force per depth >= 0 in N/m"),
            ("edge_force_radial", lambda a: a >= 0, "a force per depth >= 0 in N/m"),
            ("tool_stiffness", lambda a: a >= 0, "a stiffness >= 0 in N/m (0 = rigid)"),
            ("wear_rate", lambda a: a >= 0, "a rate >= 0 in 1/s"),
            ("spindle_droop", lambda a: a >= 0, "a droop >= 0 in (rad/s)/(N.m)"),
            ("chatter_frequency", lambda a: a >= 0, "a frequency >= 0 in Hz (0 = off)"),
            ("chatter_damping", lambda a: (a >= 0) & (a < 1), "a damping ratio in [0, 1)"),
            ("chatter_stiffness", lambda a: a >= 0, "a stiffness >= 0 in N/m"),
        )
        for name, ok, expected in checks:
            a = v[name]
            bad = np.flatnonzero(~(np.isfinite(a) & ok(a)))
            if bad.size:
                raise error(
                    f"{component}.{name}: member {int(bad[0])} has {float(a[bad[0]])!r}; expected {expected}"
                )
        on = v["chatter_frequency"] > 0
        bad = np.flatnonzero(on & ~(v["chatter_stiffness"] > 0))
        if bad.size:
            raise error(
                f"{component}.chatter_stiffness: member {int(bad[0])} has chatter_frequency "
                f"{float(v['chatter_frequency'][bad[0]])} Hz but chatter_stiffness "
                f"{float(v['chatter_stiffness'][bad[0]])}; expected a positive modal stiffness in N/m"
            )
        return cls(
            eccentricity=v["runout_eccentricity"], phase=v["runout_phase"], tan_helix=np.tan(v["helix_angle"]),
            kte=v["edge_force_tangential"], kre=v["edge_force_radial"], stiffness=v["tool_stiffness"],
            wear_rate=v["wear_rate"], droop=v["spindle_droop"],
            chatter_wn=2.0 * math.pi * v["chatter_frequency"], chatter_zeta=v["chatter_damping"],
            chatter_k=np.where(on, v["chatter_stiffness"], 0.0),
        )

    @property
    def geometric(self) -> bool:
        """Whether a term that changes the chip or the force law is on (runout, helix, edge, deflection, chatter)."""
        return bool(np.any(self.eccentricity != 0) or np.any(self.tan_helix != 0) or np.any(self.kte != 0)
                    or np.any(self.kre != 0) or np.any(self.stiffness != 0) or np.any(self.chatter_wn != 0))

    @property
    def chatter(self) -> bool:
        """Whether any member has a tool mode."""
        return bool(np.any(self.chatter_wn > 0))

    def runout_offsets(self, flutes: np.ndarray, nmax: int) -> np.ndarray:
        """Chip offsets from runout, ``r_j - r_(j+i+1)`` [m], shape (B, nmax, MAX_PASSES).

        Entry ``[m, j, i]``: tooth ``j`` cutting the surface left ``i + 1``
        teeth back stands out against that tooth by the difference of their
        radii (Kline & DeVor); 0 beyond ``flutes`` and without runout. Tooth
        ``j`` sits at ``phi = theta + j pitch`` and the spindle turns towards
        increasing ``phi``, so the tooth that passed a point one pitch earlier
        is tooth ``j + 1`` (indices mod ``flutes``).
        """
        out = np.zeros((flutes.shape[0], nmax, MAX_PASSES))
        for m in np.flatnonzero(self.eccentricity != 0):
            n = int(flutes[m])
            r = runout_radius_offsets(n, float(self.eccentricity[m]), float(self.phase[m]))
            for i in range(MAX_PASSES):
                out[m, :n, i] = r - np.roll(r, -(i + 1))
        return out

    def radius_offsets(self, flutes: np.ndarray, nmax: int) -> np.ndarray:
        """Radius change ``r_j`` of each tooth from runout [m], shape (B, nmax) (0 beyond ``flutes``)."""
        out = np.zeros((flutes.shape[0], nmax))
        for m in np.flatnonzero(self.eccentricity != 0):
            n = int(flutes[m])
            out[m, :n] = runout_radius_offsets(n, float(self.eccentricity[m]), float(self.phase[m]))
        return out

    def passes(self, flutes: np.ndarray) -> np.ndarray:
        """Surfaces each tooth may cut, shape (B,): 1 (the previous tooth's) unless runout or chatter.

        With runout a small tooth may not reach the previous surface, the next
        one then cuts the surface left ``2, 3, ...`` teeth back (up to one
        revolution, at most :data:`MAX_PASSES`); with chatter a tooth that
        jumped out of the cut leaves the older surface in place (multiple
        regeneration, :data:`MAX_PASSES` surfaces).
        """
        out = np.ones(flutes.shape[0], dtype=np.int64)
        out = np.where(self.eccentricity != 0, np.minimum(flutes, MAX_PASSES), out)
        return np.where(self.chatter_wn > 0, MAX_PASSES, out).astype(np.int64)

    def packed(self) -> np.ndarray:
        """Shape (11, B): rows as :data:`PACKED_ROWS` (for the compiled kernels)."""
        return np.stack([self.eccentricity, self.phase, self.tan_helix, self.kte, self.kre, self.stiffness,
                         self.wear_rate, self.droop, self.chatter_wn, self.chatter_zeta, self.chatter_k])


#: Rows of :meth:`EffectParameters.packed`.
PACKED_ROWS = ("eccentricity", "phase", "tan_helix", "kte", "kre", "stiffness", "wear_rate", "droop",
               "chatter_wn", "chatter_zeta", "chatter_k")
E_ECC, E_PHASE, E_TANH, E_KTE, E_KRE, E_STIFF, E_WEAR, E_DROOP, E_WN, E_ZETA, E_KC = range(11)


def runout_reach(toff: np.ndarray, passes: np.ndarray, radius_offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How far beyond the nominal radius each tooth is tested for material, m, each shape (B, nmax).

    Returns ``(sweep, stock)``: the point tested against the tool's own sweeps (the recent path; in the
    Z-map mode the near field) lies ``R + sweep`` from the axis, the point tested against the stock (the
    Z-map: the block's faces and the walls committed to it) ``R + stock``.

    ``sweep = max(0, max_(i < passes) toff[m, j, i])``: for two flutes ``max(r_j - r_(j-1), 0)``, with
    ``r_(j-1)`` the tooth that passed one pitch earlier (``toff[m, j, 0]``; the surface a revolution back
    gives ``r_j - r_j = 0``). Why: the stock stores every sweep as the nominal disc of radius ``R``, while
    the surface tooth ``j`` meets was left by tooth ``j - i - 1`` at ``R + r_(j-i-1)``. Against a nominal
    sweep the tip ``R + r_j`` stands ``r_j - r_(j-i-1)`` further out than against that real surface, so the
    point to test in the nominal sweep is ``R + r_j - r_(j-i-1)``. Its largest value over the surfaces the
    chip looks at (``passes``: one revolution with runout) lets every Kline-DeVor chip
    ``min_i (c_i . u + r_j - r_(j-i-1)) > 0`` pass the test (to first order a point ``delta`` beyond the rim
    is outside the nominal sweep of a centre displaced by ``c`` when ``c . u + delta > 0``); the chip
    minimum then decides the thickness. The tooth's own offset ``R + r_j`` would still drop the chips with
    ``-2 e < c_0 . u < -e`` (two flutes, phase 0).

    ``stock = max(r_j, 0)`` where ``sweep > 0``: the block's faces are not cut by any tooth, the tip
    ``R + r_j`` meets them where it is (a cutter with runout enters the part ``e`` early).

    A tooth standing out by no more than every tooth of the last revolution (the shortest one; every tooth
    without runout) keeps the nominal test (0 and 0: bit for bit the test without runout): it cuts nothing
    the longer teeth did not leave. Not modelled: a wall the tool left more than a revolution ago but still
    in the recent path (a reversal, a tight corner) was cut by the long tooth at ``R + max r``, so the long
    tooth meets it up to ``sweep`` early (walls committed to the Z-map: below its cell error).

    Parameters
    ----------
    toff : ndarray, shape (B, nmax, >= max(passes))
        Runout chip offsets (:meth:`EffectParameters.runout_offsets`), m.
    passes : ndarray of int, shape (B,)
        Surfaces a tooth may cut (:meth:`EffectParameters.passes`).
    radius_offsets : ndarray, shape (B, nmax)
        Each tooth's radius change ``r_j`` (:meth:`EffectParameters.radius_offsets`), m.

    Returns
    -------
    sweep, stock : ndarray, shape (B, nmax)
    """
    used = np.arange(toff.shape[2])[None, None, :] < np.asarray(passes)[:, None, None]
    sweep = np.maximum(np.where(used, toff, 0.0).max(axis=2), 0.0)
    stock = np.where(sweep > 0.0, np.maximum(radius_offsets, 0.0), 0.0)
    return sweep, stock


@njit
def helix_bands(tan_helix: float, radius: float, pitch: float, steps: float, height: float) -> tuple[int, float]:
    """Axial bands of a helical flute: ``(count, band height [m])``.

    A band of height ``dz`` lags by ``dz tan(helix) / R``; bands are as tall
    as one angular step (``pitch / steps``) of lag, from the tool tip up to
    ``height`` (the stock top above the tip), at most :data:`MAX_BANDS`. Band
    ``b`` spans ``[b dz, (b + 1) dz)`` above the tip (the last one up to
    infinity) and sits at the lag of its middle. A straight flute (or no
    material above the tip) is one band of infinite height.
    """
    if tan_helix == 0.0 or not height > 0.0:
        return 1, math.inf
    dz = pitch / steps * radius / abs(tan_helix)
    n = int(math.ceil(height / dz - 1e-9))
    if n > MAX_BANDS:
        return MAX_BANDS, height / MAX_BANDS
    return max(n, 1), dz


class EffectState:
    """What the effect terms carry between steps, per member.

    Attributes
    ----------
    cutting_time : ndarray, shape (B,)
        Time with material removal since setup [s] (the wear clock).
    torque : ndarray, shape (B,)
        Mean cutting torque of the previous step [N.m] (spindle droop, explicit).
    angle : ndarray, shape (B,)
        Unwrapped spindle angle of tooth 0 [rad] (regenerative history).
    mode : ndarray, shape (B, 4)
        Tool vibration ``qx, qy`` [m] and ``vx, vy`` [m/s].
    ht, hx, hy : ndarray, shape (B, C)
        Vibration history: unwrapped angle [rad], ``qx``, ``qy`` [m] (C = 1 when chatter is off).
    meta : ndarray of int64, shape (B, 2)
        Ring-buffer oldest index and count.
    """

    def __init__(self, batch: int, angle: np.ndarray, chatter: bool) -> None:
        cap = HISTORY_CAPACITY if chatter else 1
        self.cutting_time = np.zeros(batch)
        self.torque = np.zeros(batch)
        self.angle = np.asarray(angle, dtype=np.float64).copy()
        self.mode = np.zeros((batch, 4))
        self.ht = np.zeros((batch, cap))
        self.hx = np.zeros((batch, cap))
        self.hy = np.zeros((batch, cap))
        self.meta = np.zeros((batch, 2), dtype=np.int64)
        if chatter:  # at rest at the start
            self.ht[:, 0] = self.angle
            self.meta[:, 1] = 1
