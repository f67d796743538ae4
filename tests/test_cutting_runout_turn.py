"""A tooth standing out by runout is tested for material at its own reach, in both cutting modes.

A 2-flute end mill with eccentricity ``e`` at phase 0: tooth 0 reaches ``R + e``, tooth 1 ``R - e``. Its chip
against the surfaces left one and two teeth back (Kline-DeVor) is ``h_0 = min(c_0 . u + 2 e, c_1 . u)``, with
``c_i`` the tool-centre displacement over the last ``i + 1`` tooth periods and ``u = (sin phi, cos phi)``; the
force of a straight tooth is ``Kt a h sqrt(1 + Ke^2)`` (tangential and radial components at right angles).

* Straight slot along +x at ``fz`` per tooth: at ``phi = 90 deg`` tooth 0's chip is ``fz + 2 e``
  (``c_0 . u = fz``, ``c_1 . u = 2 fz``), tooth 1's ``fz - 2 e``.
* 90 deg left turn (+x, then +y from a sharp corner at a step boundary), ``tau`` = 4 ms after the corner at
  ``fz`` = 50 um (tooth period 5 ms): ``c_0 = (v (T_z - tau), v tau) = (10, 40) um``, ``c_1 = (60, 40) um``.
  At the ``phi`` where ``c_0 . u = -3 um`` tooth 0 cuts ``min(-3 + 2 e, c_1 . u) = 17 um`` (``e`` = 10 um).
  The nominal periphery point ``R`` lies 12.5 um inside the tool's disc at the corner
  (``(C - corner) . u = 40 um cos(phi)``), so the test at the nominal radius dropped this chip (0 N, both
  modes; the material test at ``R + 2 e`` passes it). The README's force-only case showed the same:
  misfits of 13-25 N at single samples of the step-over corner.

The path mode tests the long tooth in its table's runout ring (25 um beyond the radius against the sweeps,
12.5 um against the block; the Z-map mode at exactly 2 e and e): the same numbers here, away from the block's faces.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.cutting import CuttingLoad
from fmus_src.cutting.path_component import PathCuttingLoad
from fmus_src.cutting.table import EngagementTable

KT, KE = 1.23e9, 0.5  # CuttingLoad defaults (A6061), N/m2, 1
R = 3e-3  # tool radius, m
DEPTH = 1e-3  # slot depth, m
ECC = 10e-6  # eccentricity, m (phase 0: tooth 0 is the long one)
RPM = 6000.0
OMEGA = RPM * 2.0 * math.pi / 60.0
TZ = 60.0 / RPM / 2.0  # tooth period, s (5 ms)
FZ = 50e-6  # feed per tooth, m
V = FZ / TZ  # feed, m/s (600 mm/min)
H = 1e-3  # communication step, s
X0, XC = -5.5e-3, 0.0  # start (beside the stock) and corner, m
TAU = 4e-3  # time after the corner of the turn sample, s
C0_U = -3e-6  # tooth 0's c_0 . u at the turn sample, m


def _turn_angle() -> float:
    """The immersion angle in (90, 180) deg where ``c_0 . u = C0_U`` at the turn sample, rad."""
    a, b = V * (TZ - TAU), V * TAU  # c_0 = (a, b); phi = pi/2 + beta: a cos(beta) - b sin(beta) = C0_U
    return 0.5 * math.pi + math.acos(C0_U / math.hypot(a, b)) - math.atan2(b, a)


def _schedule() -> tuple[np.ndarray, np.ndarray, float, float, float]:
    """Step end times and XY positions (1 ms grid, plus the straight-leg instant with tooth 0 at 90 deg).

    Returns times (s), positions (m, shape (K, 3) at depth), the initial spindle angle, the turn sample time
    and the straight sample time.
    """
    t_corner = (XC - X0) / V
    t_turn = t_corner + TAU
    phi = _turn_angle()
    theta0 = phi - OMEGA * t_turn
    # tooth 0 at 90 deg (mod 2 pi) on the straight leg, four revolutions before the turn sample
    t_straight = t_turn - (phi - 0.5 * math.pi) / OMEGA - 4 * 2 * TZ
    grid = np.arange(0.0, t_turn + 0.5 * H, H)
    t = np.unique(np.concatenate([grid, [t_straight, t_turn]]))
    x = np.where(t <= t_corner, X0 + V * t, XC)
    y = np.where(t <= t_corner, 0.0, V * (t - t_corner))
    pos = np.stack([x, y, np.full_like(t, -DEPTH)], axis=1)
    return t, pos, theta0, t_turn, t_straight


def _params() -> dict:
    return dict(tool_diameter=2 * R, flutes=2, kt=KT, ke=KE, stock_x_min=-5e-3, stock_x_max=5e-3,
                stock_y_min=-5e-3, stock_y_max=5e-3, stock_z_min=-5e-3, stock_z_max=0.0,
                runout_eccentricity=ECC, runout_phase=0.0)


def _run(comp, t: np.ndarray, pos: np.ndarray, theta0: float) -> dict[float, float]:
    """|F| (N) after each step of ``comp`` driven through ``pos`` at the times ``t``."""
    comp.set("initial_spindle_angle", theta0)
    comp.set("spindle_speed", OMEGA)
    for a, name in enumerate(("x_position", "y_position", "z_position")):
        comp.set(name, pos[0, a])
    comp.setup(0.0)
    out = {}
    for k in range(1, t.size):
        for a, name in enumerate(("x_position", "y_position", "z_position")):
            comp.set(name, pos[k, a])
        comp.do_step(float(t[k - 1]), float(t[k] - t[k - 1]))
        out[float(t[k])] = math.hypot(float(comp.get("fx")[0]), float(comp.get("fy")[0]))
    return out


def _hand(h: float) -> float:
    return KT * DEPTH * h * math.sqrt(1.0 + KE * KE)


@pytest.fixture(scope="module")
def runs() -> tuple[dict[str, dict[float, float]], float, float]:
    t, pos, theta0, t_turn, t_straight = _schedule()
    zmap = _run(CuttingLoad("cut", **_params()), t, pos, theta0)
    path = PathCuttingLoad("cut", **_params())
    path.attach_table(EngagementTable.from_parameters(pos, _params()))
    return {"zmap": zmap, "path": _run(path, t, pos, theta0)}, t_turn, t_straight


@pytest.mark.parametrize("mode", ["zmap", "path"])
def test_the_long_tooth_cuts_fz_plus_2e_in_a_straight_slot(runs, mode):
    forces, _, t_straight = runs
    # tooth 0 (R + e) at 90 deg: min(fz + 2 e, 2 fz) = 70 um; tooth 1 at 270 deg is behind the feed
    assert forces[mode][t_straight] == pytest.approx(_hand(FZ + 2 * ECC), rel=1e-6)  # 96.3 N


@pytest.mark.parametrize("mode", ["zmap", "path"])
def test_the_long_tooth_keeps_its_chip_at_a_turn(runs, mode):
    forces, t_turn, _ = runs
    phi = _turn_angle()
    u = np.array([math.sin(phi), math.cos(phi)])
    c0 = np.array([V * (TZ - TAU), V * TAU])
    c1 = np.array([V * (2 * TZ - TAU), V * TAU])
    assert float(c0 @ u) == pytest.approx(C0_U, abs=1e-12)
    h = min(float(c0 @ u) + 2 * ECC, float(c1 @ u))  # 17 um
    assert h == pytest.approx(17e-6, abs=1e-12)
    # tooth 1 (R - e) at phi + 180 deg: min(-c_0 . u - 2 e, -c_1 . u) < 0, no chip
    assert forces[mode][t_turn] == pytest.approx(_hand(h), rel=1e-6)  # 23.4 N (0 N before)
