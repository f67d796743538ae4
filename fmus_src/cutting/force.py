"""Mechanistic milling forces (Sim & Lee 2023, Eq. 10-13; Altintas ch. 2).

Angles follow :mod:`.engagement`: ``phi`` clockwise from +y, tool turning
clockwise seen from the spindle. For a tooth at ``phi`` with axial depth ``d``:

* chip thickness ``h = max(dx sin phi + dy cos phi, 0)`` where ``(dx, dy)`` is
  the tool-centre displacement per tooth period ``2 pi / (N omega)`` (the feed
  per tooth vector projected on the tooth's radial direction);
* tangential force ``Ft = Kt d h``, radial force ``Fr = Ke Ft``;
* force **on the tool**: the tangential force opposes the tooth velocity
  ``(cos phi, -sin phi)``, the radial force pushes the tooth towards the
  centre ``-(sin phi, cos phi)``::

      Fx = -Ft cos phi - Fr sin phi
      Fy = +Ft sin phi - Fr cos phi

Summed over teeth this is exactly Eq. (10)-(11) of the paper,
``[Fx Fy] = 1/2 d Kt [a11 a12; a21 a22] [dx dy]`` with::

      a11 = -sum g [sin 2phi + Ke (1 - cos 2phi)]
      a12 = -sum g [(1 + cos 2phi) + Ke sin 2phi]
      a21 = +sum g [(1 - cos 2phi) - Ke sin 2phi]
      a22 = +sum g [sin 2phi - Ke (1 + cos 2phi)]

The paper prints a minus sign in front of ``a21`` (printed "a13") and ``a22``;
with one consistent convention for x and y those two terms carry a plus sign
(Altintas, Eq. 3.10): the paper's ``Fy`` is the y force with the opposite
sign. The cutting load ``Fc = sqrt(Fx^2 + Fy^2)`` (Eq. 13) does not depend on
that sign. The component outputs the force **on the workpiece**, the negative
of the force on the tool.

Compared with the paper the chip thickness is clipped at zero (a tooth on the
trailing side does not pull) and the axial depth is per tooth, from the stock.
"""
from __future__ import annotations

import numpy as np


def chip_thickness(dx: np.ndarray, dy: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Instantaneous uncut chip thickness, m.

    Parameters
    ----------
    dx, dy : ndarray
        Tool-centre displacement per tooth period, m (broadcast with ``phi``).
    phi : ndarray
        Tooth immersion angle, rad.

    Returns
    -------
    ndarray
        ``max(dx sin phi + dy cos phi, 0)``.
    """
    return np.maximum(dx * np.sin(phi) + dy * np.cos(phi), 0.0)


def tooth_forces_on_tool(
    kt: np.ndarray, ke: np.ndarray, depth: np.ndarray, h: np.ndarray, phi: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Force of one tooth on the tool in machine axes.

    Parameters
    ----------
    kt : ndarray
        Tangential cutting coefficient, N/m2.
    ke : ndarray
        Radial / tangential force ratio, 1.
    depth : ndarray
        Axial depth of cut of the tooth, m.
    h : ndarray
        Chip thickness, m.
    phi : ndarray
        Immersion angle, rad. All arguments broadcast.

    Returns
    -------
    fx, fy : ndarray
        Force on the tool, N.
    ft : ndarray
        Tangential force, N (torque = ``ft R``).
    """
    ft = kt * depth * h
    fr = ke * ft
    s = np.sin(phi)
    c = np.cos(phi)
    return -ft * c - fr * s, ft * s - fr * c, ft


def paper_matrix(phi: np.ndarray, engaged: np.ndarray, ke: float) -> np.ndarray:
    """Directional matrix of Eq. (11) with consistent signs (see module docstring).

    Parameters
    ----------
    phi : ndarray, shape (N,)
        Tooth angles, rad.
    engaged : ndarray of bool, shape (N,)
        ``g(phi_j)``.
    ke : float
        Radial / tangential ratio.

    Returns
    -------
    ndarray, shape (2, 2)
        ``A`` such that force on the tool = ``d Kt / 2 · A · [dx, dy]`` (all teeth
        with ``h >= 0``).
    """
    g = np.asarray(engaged, dtype=np.float64)
    s2 = np.sin(2.0 * phi)
    c2 = np.cos(2.0 * phi)
    return np.array([
        [-np.sum(g * (s2 + ke * (1.0 - c2))), -np.sum(g * ((1.0 + c2) + ke * s2))],
        [np.sum(g * ((1.0 - c2) - ke * s2)), np.sum(g * (s2 - ke * (1.0 + c2)))],
    ])


def average_forces_on_tool(
    kt: float, ke: float, depth: float, feed_per_tooth: float, flutes: int, phi_st: float, phi_ex: float
) -> tuple[float, float]:
    """Closed-form mean force on the tool over a tooth period, feed along +x.

    Altintas, *Manufacturing Automation*, Eq. (2.31) with ``Kte = Kre = 0``::

        Fx = N a c / (8 pi) [Kt cos 2phi - Kr (2phi - sin 2phi)]  from phi_st to phi_ex
        Fy = N a c / (8 pi) [Kt (2phi - sin 2phi) + Kr cos 2phi]  from phi_st to phi_ex

    for ``0 <= phi_st < phi_ex <= pi`` (the chip thickness ``c sin phi`` is then
    non-negative); the mean of several teeth adds linearly, hence the factor ``N``.

    Returns
    -------
    fx, fy : float
        Mean force on the tool, N.
    """
    kr = ke * kt

    def fx(p: float) -> float:
        return kt * np.cos(2 * p) - kr * (2 * p - np.sin(2 * p))

    def fy(p: float) -> float:
        return kt * (2 * p - np.sin(2 * p)) + kr * np.cos(2 * p)

    k = flutes * depth * feed_per_tooth / (8.0 * np.pi)
    return float(k * (fx(phi_ex) - fx(phi_st))), float(k * (fy(phi_ex) - fy(phi_st)))


def tooth_quantities(
    kt: np.ndarray, ke: np.ndarray, depth: np.ndarray, h: np.ndarray, phi: np.ndarray,
    radius: np.ndarray, omega: np.ndarray,
) -> np.ndarray:
    """Per-tooth force on the tool, torque and removal rate at one instant.

    Parameters
    ----------
    kt, ke, depth, h, phi : ndarray
        As in :func:`tooth_forces_on_tool`.
    radius : ndarray
        Tool radius, m.
    omega : ndarray
        Spindle speed, rad/s. All arguments broadcast to a shape ``S``.

    Returns
    -------
    ndarray, shape S + (4,)
        ``(Fx, Fy)`` on the tool in N, torque ``Ft R`` in N.m, removal rate
        ``h d R omega`` in m3/s.
    """
    fx, fy, ft = tooth_forces_on_tool(kt, ke, depth, h, phi)
    return np.stack(np.broadcast_arrays(fx, fy, ft * radius, h * depth * radius * omega), axis=-1)


def interval_mean_quantities(
    kt: np.ndarray, ke: np.ndarray, depth: np.ndarray, dx: np.ndarray, dy: np.ndarray,
    phi_a: np.ndarray, phi_b: np.ndarray, radius: np.ndarray, omega: np.ndarray,
) -> np.ndarray:
    """Exact mean of :func:`tooth_quantities` while a tooth turns from ``phi_a`` to ``phi_b``.

    The axial depth and the feed per tooth ``(dx, dy)`` are constant over the
    interval; the chip thickness ``h = max(dx sin phi + dy cos phi, 0)`` is
    integrated in closed form (products of sines and cosines), splitting the
    interval where ``h`` changes sign. The interval must be shorter than
    ``pi`` (at most one sign change). With the spindle turning at constant
    speed the mean over the angle is the mean over time.

    Parameters
    ----------
    kt, ke, depth, radius, omega : ndarray
        As in :func:`tooth_quantities`.
    dx, dy : ndarray
        Feed per tooth vector, m.
    phi_a, phi_b : ndarray
        Start and end angle, rad (``phi_b >= phi_a``; equal angles give the
        instantaneous value). All arguments broadcast to a shape ``S``.

    Returns
    -------
    ndarray, shape S + (4,)
        Mean ``(Fx, Fy)`` on the tool (N), torque (N.m), removal rate (m3/s).
    """
    span = phi_b - phi_a
    h_a = dx * np.sin(phi_a) + dy * np.cos(phi_a)
    h_b = dx * np.sin(phi_b) + dy * np.cos(phi_b)
    psi = np.arctan2(dy, dx)
    phi_zero = phi_a + np.mod(-psi - phi_a, np.pi)
    lo = np.where((h_a >= 0.0) | (h_b < 0.0), phi_a, np.minimum(phi_zero, phi_b))
    hi = np.where(h_b >= 0.0, phi_b, np.where(h_a > 0.0, np.minimum(phi_zero, phi_b), phi_a))
    hi = np.where((h_a < 0.0) & (h_b < 0.0), lo, hi)

    def primitives(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        s, c = np.sin(p), np.cos(p)
        s2 = np.sin(2.0 * p)
        half_sq = 0.5 * s * s
        i_hcos = dx * half_sq + dy * (0.5 * p + 0.25 * s2)  # int h cos
        i_hsin = dx * (0.5 * p - 0.25 * s2) + dy * half_sq  # int h sin
        i_h = -dx * c + dy * s  # int h
        return i_hcos, i_hsin, i_h

    u = primitives(lo)
    w = primitives(hi)
    short = span < 1e-9
    span_safe = np.where(short, 1.0, span)
    i_hcos, i_hsin, i_h = ((wk - uk) / span_safe for wk, uk in zip(w, u))
    mean = np.stack(np.broadcast_arrays(
        -kt * depth * (i_hcos + ke * i_hsin),
        kt * depth * (i_hsin - ke * i_hcos),
        kt * depth * radius * i_h,
        depth * radius * omega * i_h,
    ), axis=-1)
    phi_m = 0.5 * (phi_a + phi_b)
    point = tooth_quantities(kt, ke, depth, chip_thickness(dx, dy, phi_m), phi_m, radius, omega)
    return np.where(np.asarray(short)[..., None], point, mean)
