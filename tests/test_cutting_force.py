"""Pure force functions of fmus_src.cutting.force against hand-derived expressions."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

from fmus_src.cutting.force import (
    average_forces_on_tool,
    chip_thickness,
    interval_mean_quantities,
    paper_matrix,
    tooth_forces_on_tool,
    tooth_quantities,
)

KT, KE = 1.23e9, 0.5


def test_chip_thickness_is_feed_projection_clipped_at_zero():
    # feed along +x: h = c sin(phi); tooth at +x (phi = pi/2) gets the full feed, trailing side none
    c = 5e-5
    assert chip_thickness(c, 0.0, math.pi / 2) == pytest.approx(c)
    assert chip_thickness(c, 0.0, math.pi / 6) == pytest.approx(c / 2)
    assert chip_thickness(c, 0.0, 3 * math.pi / 2) == 0.0
    # feed along +y: the tooth pointing to +y (phi = 0) gets it
    assert chip_thickness(0.0, c, 0.0) == pytest.approx(c)


def test_tooth_force_directions():
    # tooth at phi = pi/2 points to +x and moves towards -y (clockwise): the chip pushes the tool
    # to +y (tangential, against the tooth velocity) and to -x (radial, towards the centre)
    fx, fy, ft = tooth_forces_on_tool(KT, KE, 2e-3, 5e-5, math.pi / 2)
    assert ft == pytest.approx(KT * 2e-3 * 5e-5)
    assert fx == pytest.approx(-KE * ft)
    assert fy == pytest.approx(ft)


def test_sum_of_teeth_equals_eq10_matrix_form():
    rng = np.random.default_rng(1)
    for _ in range(20):
        n = int(rng.integers(1, 5))
        phi = rng.uniform(0, 2 * np.pi, n)
        # feed direction chosen so that every tooth has h >= 0 (Eq. 10 is linear, without clipping)
        psi = rng.uniform(0, 2 * np.pi)
        f = 4e-5
        d = np.array([f * math.cos(psi), f * math.sin(psi)])
        h = d[0] * np.sin(phi) + d[1] * np.cos(phi)
        engaged = h >= 0
        depth = 1.5e-3
        fx, fy, _ = tooth_forces_on_tool(KT, KE, depth, np.where(engaged, h, 0.0), phi)
        expected = 0.5 * depth * KT * paper_matrix(phi, engaged, KE) @ d
        assert np.sum(fx) == pytest.approx(expected[0], rel=1e-12, abs=1e-9)
        assert np.sum(fy) == pytest.approx(expected[1], rel=1e-12, abs=1e-9)


@pytest.mark.parametrize("phi_st, phi_ex", [(0.0, math.pi), (0.0, math.pi / 2), (math.pi / 2, math.pi),
                                            (0.0, math.acos(0.5)), (math.acos(-0.5), math.pi)])
def test_closed_form_average_matches_quadrature(phi_st, phi_ex):
    n, a, c = 2, 2e-3, 5e-5

    def fx(p):  # hand-written instantaneous force on the tool, one tooth, h = c sin p
        ft = KT * a * c * math.sin(p)
        return -ft * math.cos(p) - KE * ft * math.sin(p)

    def fy(p):
        ft = KT * a * c * math.sin(p)
        return ft * math.sin(p) - KE * ft * math.cos(p)

    pitch = 2 * math.pi / n
    ex = quad(fx, phi_st, phi_ex)[0] / pitch
    ey = quad(fy, phi_st, phi_ex)[0] / pitch
    got = average_forces_on_tool(KT, KE, a, c, n, phi_st, phi_ex)
    assert got[0] == pytest.approx(ex, rel=1e-10, abs=1e-9)
    assert got[1] == pytest.approx(ey, rel=1e-10, abs=1e-9)


def test_slot_average_special_values():
    # full slot: mean Fx = -N a c Kr / 4, mean Fy = +N a c Kt / 4 on the tool (Altintas Eq. 2.31)
    n, a, c = 2, 2e-3, 5e-5
    fx, fy = average_forces_on_tool(KT, KE, a, c, n, 0.0, math.pi)
    assert fx == pytest.approx(-n * a * c * KE * KT / 4)
    assert fy == pytest.approx(n * a * c * KT / 4)
    assert (fx, fy) == pytest.approx((-30.75, 61.5))


def test_interval_mean_is_exact_including_sign_change():
    rng = np.random.default_rng(2)
    radius, omega, depth = 3e-3, 800.0, 1e-3
    for _ in range(30):
        dx, dy = rng.normal(size=2) * 3e-5
        a = rng.uniform(0, 2 * np.pi)
        b = a + rng.uniform(0.01, 3.0)
        got = interval_mean_quantities(KT, KE, depth, dx, dy, a, b, radius, omega)
        # zeros of h = dx sin p + dy cos p: p = -atan2(dy, dx) + m pi (kinks of the clipped integrand)
        psi = math.atan2(dy, dx)
        kinks = [z for z in (-psi + m * math.pi for m in range(-2, 6)) if a < z < b]
        for k in range(4):
            def integrand(p, k=k):
                return tooth_quantities(KT, KE, depth, chip_thickness(dx, dy, p), p, radius, omega)[k]
            ref = quad(integrand, a, b, points=kinks or None, limit=200, epsabs=0, epsrel=1e-12)[0] / (b - a)
            assert got[k] == pytest.approx(ref, rel=1e-8, abs=1e-12 * (1 + abs(ref)))


def test_interval_mean_of_zero_length_is_the_point_value():
    q = interval_mean_quantities(KT, KE, 1e-3, 5e-5, 0.0, 1.0, 1.0, 3e-3, 800.0)
    p = tooth_quantities(KT, KE, 1e-3, chip_thickness(5e-5, 0.0, 1.0), 1.0, 3e-3, 800.0)
    assert np.allclose(q, p)
