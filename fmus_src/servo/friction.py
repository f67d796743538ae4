"""Direction-dependent Stribeck friction of a feed drive (Sim & Lee 2023, Eq. 3).

.. math::

    F_f(\\dot x) = \\mu_v \\dot x + \\operatorname{sign}(\\dot x)
                   \\{F_c + (F_s - F_c)\\, e^{-|\\dot x| / v_s}\\}

with a separate parameter set for positive and negative motion (Table 1 of
the paper). All magnitudes are positive numbers; the force opposes the
motion. At zero velocity the friction is *static*: it balances the applied
force up to the break-away force ``Fs`` of the direction the table would
move (handled by :mod:`fmus_src.servo.stick_slip`).

All functions are vectorised over the batch: every argument is a float or an
array broadcastable to shape ``(B,)``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class StribeckParameters:
    """Stribeck friction parameters of both directions, arrays of shape (B,).

    Attributes
    ----------
    coulomb_pos, coulomb_neg : ndarray
        Coulomb friction magnitude ``Fc`` [N] for positive / negative motion.
    static_pos, static_neg : ndarray
        Static (break-away) friction magnitude ``Fs`` [N].
    stribeck_velocity_pos, stribeck_velocity_neg : ndarray
        Stribeck velocity magnitude ``vs`` [m/s], > 0.
    viscous_pos, viscous_neg : ndarray
        Viscous coefficient ``mu_v`` [N.s/m].
    """

    coulomb_pos: np.ndarray
    static_pos: np.ndarray
    stribeck_velocity_pos: np.ndarray
    viscous_pos: np.ndarray
    coulomb_neg: np.ndarray
    static_neg: np.ndarray
    stribeck_velocity_neg: np.ndarray
    viscous_neg: np.ndarray

    def take(self, index: np.ndarray) -> "StribeckParameters":
        """Parameters of the batch members ``index`` (integer index array)."""
        return StribeckParameters(*(getattr(self, f)[index] for f in self.__dataclass_fields__))

    def select(self, direction: np.ndarray) -> "DirectedFriction":
        """Parameters of the branch ``direction`` (+1 or -1; 0 gives the negative branch), shape (B,)."""
        pos = direction > 0
        return DirectedFriction(
            coulomb=np.where(pos, self.coulomb_pos, self.coulomb_neg),
            delta=np.where(pos, self.static_pos - self.coulomb_pos, self.static_neg - self.coulomb_neg),
            inv_stribeck_velocity=np.where(pos, 1.0 / self.stribeck_velocity_pos, 1.0 / self.stribeck_velocity_neg),
            viscous=np.where(pos, self.viscous_pos, self.viscous_neg),
        )


@dataclass(frozen=True)
class DirectedFriction:
    """One Stribeck branch per batch member (the direction already chosen).

    Attributes
    ----------
    coulomb : ndarray
        ``Fc`` [N], shape (B,).
    delta : ndarray
        ``Fs - Fc`` [N], shape (B,).
    inv_stribeck_velocity : ndarray
        ``1 / vs`` [s/m], shape (B,).
    viscous : ndarray
        ``mu_v`` [N.s/m], shape (B,).
    """

    coulomb: np.ndarray
    delta: np.ndarray
    inv_stribeck_velocity: np.ndarray
    viscous: np.ndarray

    def take(self, index: np.ndarray) -> "DirectedFriction":
        """Branch parameters of the batch members ``index`` (integer index array)."""
        return DirectedFriction(*(getattr(self, f)[index] for f in self.__dataclass_fields__))

    def force(self, v: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """Sliding friction [N] of branch ``direction`` at velocity ``v`` [m/s].

        For ``direction * v >= 0`` this is exactly Eq. (3). For the other sign
        (only ever evaluated inside a Runge-Kutta stage or a root search that
        straddles a zero crossing) the branch is continued with the
        exponential frozen at 1, i.e. ``mu_v v + direction * Fs``; this
        continuation is continuous at ``v = 0`` and bounded, so a stage that
        overshoots zero cannot blow up.
        """
        s_v = np.maximum(direction * v, 0.0)
        return self.viscous * v + direction * (
            self.coulomb + self.delta * np.exp(-s_v * self.inv_stribeck_velocity)
        )


def stribeck_force(v: np.ndarray | float, params: StribeckParameters) -> np.ndarray:
    """Sliding friction of Eq. (3) at velocity ``v`` with the branch of its sign.

    Parameters
    ----------
    v : float or ndarray, shape (B,)
        Table velocity [m/s].
    params : StribeckParameters
        Both branches, arrays of shape (B,).

    Returns
    -------
    ndarray, shape (B,)
        Friction force [N], opposing the motion (same sign as ``v``); 0 at
        ``v == 0`` (the static case is not a function of velocity).
    """
    v = np.asarray(v, dtype=float)
    direction = np.sign(v)
    return params.select(direction).force(v, direction)
