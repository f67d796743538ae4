"""``locate``'s bounding-box pruning returns what the full scan returns, bit for bit.

The reference below is ``locate`` as it was before the pruning (every segment in the window projected), compiled
by numba the same way (the same loop in plain Python differs in the last bit of a distance). Seeded random polylines (dense,
sparse, with reversals) and points near and far from them, windows of every length.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from fmus_src.cutting.path_kernel import TIE_TOL, locate


@numba.njit
def _locate_full(px, py, pz, seg0, s_cur, reach, verts, vs):
    nv = verts.shape[0]
    best_d = math.inf
    best_s = s_cur
    best_seg = seg0
    seg = seg0
    while seg < nv - 1:
        s_a = vs[seg]
        if s_a > s_cur + reach:
            break
        length = vs[seg + 1] - s_a
        ax, ay, az = verts[seg, 0], verts[seg, 1], verts[seg, 2]
        dx, dy, dz = verts[seg + 1, 0] - ax, verts[seg + 1, 1] - ay, verts[seg + 1, 2] - az
        u = ((px - ax) * dx + (py - ay) * dy + (pz - az) * dz) / (length * length)
        u_min = max((s_cur - s_a) / length, 0.0)
        u = min(max(u, u_min), 1.0)
        d = math.sqrt((px - ax - u * dx) ** 2 + (py - ay - u * dy) ** 2 + (pz - az - u * dz) ** 2)
        if d < best_d - TIE_TOL:
            best_d = d
            best_s = s_a + u * length
            best_seg = seg
        seg += 1
    return best_seg, best_s, best_d


def test_pruned_locate_equals_the_full_scan():
    rng = np.random.default_rng(3)
    checked = 0
    for n, step in ((400, 1e-5), (60, 2e-3), (200, 1e-4)):
        turns = np.cumsum(rng.normal(0.0, 0.6, n))
        d = np.stack([np.cos(turns), np.sin(turns), rng.normal(0.0, 0.2, n)], axis=1) * step
        d[rng.random(n) < 0.05] *= -1.0                     # reversals
        verts = np.concatenate([np.zeros((1, 3)), np.cumsum(d, axis=0)]) + np.array([0.05, -0.02, 0.01])
        vs = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(verts, axis=0), axis=1))])
        for _ in range(600):
            seg0 = int(rng.integers(0, n - 1))
            s_cur = vs[seg0] + rng.uniform(0.0, 1.0) * (vs[seg0 + 1] - vs[seg0])
            near = verts[min(seg0 + int(rng.integers(0, 5)), n)]
            p = near + rng.normal(0.0, step * 10.0 ** rng.uniform(-4, 2), 3)
            reach = step * 10.0 ** rng.uniform(-1, 2.5)
            got = locate(p[0], p[1], p[2], seg0, s_cur, reach, verts, vs)
            want = _locate_full(p[0], p[1], p[2], seg0, s_cur, reach, verts, vs)
            assert got[0] == want[0] and got[1] == want[1] and got[2] == want[2], (got, want)
            checked += 1
    assert checked == 1800
