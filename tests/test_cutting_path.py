"""Path mode (engagement table + PathCuttingLoad) against the Z-map mode and closed-form mechanics.

The Z-map mode (CuttingLoad) is the reference: both modes see the same material (the table is
built by a reference pass with the same Z-map and near-field rules), so on the same motion the
forces agree up to the table discretisation (station spacing 20 um, boundaries interpolated
between stations) and the Z-map mode's own entry/exit location (1/4096 substep). Tolerance:
step means and peaks within TOL = 0.5 % of the peak cutting load of the run. The closed-form
means (Altintas ch. 2, see test_cutting_component) are re-derived here for the path mode.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.cutting import CuttingError, CuttingLoad
from fmus_src.cutting import table as table_module
from fmus_src.cutting.path_component import PathCuttingLoad
from fmus_src.cutting.path_kernel import locate, table_at, table_at_from
from fmus_src.cutting.table import EngagementTable, build_engagement_table

KT, KE = 1.23e9, 0.5
R = 3e-3
N = 2
H = 1e-3
TOOTH_PERIOD = 3.8e-3
OMEGA = 2 * math.pi / (N * TOOTH_PERIOD)
TOL = 5e-3
NAMES = ("fx_mean", "fy_mean", "fc_peak", "spindle_torque", "mrr", "fc", "fx", "fy", "spindle_angle")


def params(**kw):
    p = dict(tool_diameter=2 * R, flutes=N, kt=KT, ke=KE, stock_x_min=0.0, stock_x_max=0.012,
             stock_y_min=-0.01, stock_y_max=0.01, stock_z_min=-0.01, stock_z_max=0.0)
    p.update(kw)
    return p


def along(vertices, step_length):
    """Points every step_length (m, per member) along a polyline, start included; shape (K, B, 3)."""
    v = np.asarray(vertices, float)
    s_v = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(v, axis=0), axis=1))])
    step_length = np.atleast_1d(np.asarray(step_length, float))
    k = int(math.ceil(s_v[-1] / step_length.min()))
    s = np.minimum(np.arange(k + 1)[:, None] * step_length[None, :], s_v[-1])  # (K, B)
    out = np.empty(s.shape + (3,))
    for a in range(3):
        out[..., a] = np.interp(s, s_v, v[:, a])
    return out


def step_through(comp, pos, k0, names=NAMES):
    """Step a set-up component through pos[k0:] (shape (K, B, 3)); returns {name: (K - k0, B)}."""
    out = {n: [] for n in names}
    for k in range(k0, pos.shape[0]):
        for a, name in enumerate(("x_position", "y_position", "z_position")):
            comp.set(name, pos[k, :, a])
        comp.do_step((k - 1) * H, H)
        for n in names:
            out[n].append(comp.get(n))
    return {n: np.array(v) for n, v in out.items()}


def drive(comp, pos, omega, names=NAMES):
    """Set up at pos[0] and step through pos[1:] (shape (K, B, 3)); returns dict of (K-1, B) arrays."""
    for a, name in enumerate(("x_position", "y_position", "z_position")):
        comp.set(name, pos[0, :, a])
    comp.set("spindle_speed", omega)
    comp.setup(0.0)
    return step_through(comp, pos, 1, names)


def path_run(p, vertices, pos, omega, **kw):
    table = EngagementTable.from_parameters(np.asarray(vertices, float), p)
    comp = PathCuttingLoad("cut", batch=pos.shape[1], **p, **kw)
    comp.attach_table(table)
    return drive(comp, pos, omega), comp


def zmap_run(p, pos, omega):
    return drive(CuttingLoad("cut", batch=pos.shape[1], **p), pos, omega)


def assert_modes_agree(z, q, tol=TOL, worst=TOL):
    """Means, peaks, torque, MRR within tol of the run's peak; returns the steps the Z-map mode missed.

    The Z-map mode sees material only at its substep instants (and between two instants whose
    states differ), so it misses an engaged arc narrower than its substep angle (4.7 deg here)
    when no instant falls inside it, e.g. a tooth clipping a block corner. Such steps (Z-map
    peak exactly 0) are returned for an independent check and must stay rare.
    """
    peak = z["fc_peak"].max()
    assert peak > 10.0
    missed = np.zeros(z["fc_peak"].shape, bool)
    for n in ("fx_mean", "fy_mean", "fc_peak"):
        missed |= (np.abs(z[n] - q[n]) > tol * peak) & (z["fc_peak"] == 0.0)
    # an arc with material but no force (e.g. the short tooth of a cutter with runout) carries MRR only
    missed |= (np.abs(z["mrr"] - q["mrr"]) > tol * z["mrr"].max()) & (z["fc_peak"] == 0.0) & (q["fc_peak"] == 0.0)
    for n in ("fx_mean", "fy_mean", "fc_peak"):
        err = np.abs(z[n] - q[n])[~missed]
        assert err.max() <= worst * peak, n
        assert np.mean(err > tol * peak) <= 0.01, n
    assert missed.mean() <= 0.01
    ok = ~missed
    assert np.abs(z["spindle_torque"] - q["spindle_torque"])[ok].max() <= worst * peak * R * 1.2
    assert np.abs(z["mrr"] - q["mrr"])[ok].max() <= worst * z["mrr"].max()
    assert q["spindle_angle"] == pytest.approx(z["spindle_angle"], abs=1e-12)
    # instantaneous samples: equal except where a sample instant falls within the table resolution
    # of an entry/exit angle (a jump of one tooth's force)
    bad = np.abs(z["fc"] - q["fc"]) > tol * peak
    assert bad.mean() <= 0.005
    return missed


def brute_force_means(pos, k, stock_min, stock_max, a, samples=200_000):
    """Step k mean force on the workpiece, straight +x cut at y = 0 through a fresh block, by time sampling.

    Feeding along +x on a straight line the front half (sin phi > 0) of the periphery is fresh,
    the rear half was swept: a tooth cuts when sin phi > 0 and its periphery point is in the block.
    """
    t = (np.arange(samples) + 0.5) / samples
    cx = pos[k, 0, 0] + t * (pos[k + 1, 0, 0] - pos[k, 0, 0])
    c = (pos[k + 1, 0, 0] - pos[k, 0, 0]) / H * TOOTH_PERIOD
    f = np.zeros(2)
    for j in range(N):
        phi = OMEGA * H * (k + t) + j * 2 * math.pi / N
        s, co = np.sin(phi), np.cos(phi)
        px, py = cx + R * s, R * co
        inside = (s > 0) & (px >= stock_min[0]) & (px < stock_max[0]) & (py >= stock_min[1]) & (py < stock_max[1])
        ft = KT * a * c * s * inside
        f += [np.mean(-ft * co - KE * ft * s), np.mean(ft * s - KE * ft * co)]
    return -f


def mean_force_on_workpiece(a, c, p_st, p_ex):
    kr = KE * KT
    fx = lambda p: KT * math.cos(2 * p) - kr * (2 * p - math.sin(2 * p))  # noqa: E731
    fy = lambda p: KT * (2 * p - math.sin(2 * p)) + kr * math.cos(2 * p)  # noqa: E731
    k = N * a * c / (8 * math.pi)
    return np.array([-k * (fx(p_ex) - fx(p_st)), -k * (fy(p_ex) - fy(p_st))])


# ---------------------------------------------------------------------------- against the Z-map mode
@pytest.mark.parametrize("case", ["slot", "up25", "down25"])
def test_straight_cut_through_the_part_matches_zmap_mode(case):
    # entering the block face x = 0, steady cut, leaving through x = 12 mm; slot or 25 % immersion
    a, c, ae = 2e-3, 5e-5, 1.5e-3
    stock = {"slot": {}, "up25": dict(stock_y_min=R - ae), "down25": dict(stock_y_max=-(R - ae))}[case]
    p = params(**stock)
    verts = [[-R - 0.5e-3, 0.0, -a], [0.012 + R + 0.5e-3, 0.0, -a]]
    pos = along(verts, c / TOOTH_PERIOD * H)
    z = zmap_run(p, pos, OMEGA)
    q, _ = path_run(p, verts, pos, OMEGA)
    missed = assert_modes_agree(z, q)
    # where the Z-map sampling missed a narrow arc (block corner), the path mode is right
    lo, hi = (p["stock_x_min"], p["stock_y_min"]), (p["stock_x_max"], p["stock_y_max"])
    for k in np.flatnonzero(missed[:, 0]):
        exact = brute_force_means(pos, k, lo, hi, a)
        assert [q["fx_mean"][k, 0], q["fy_mean"][k, 0]] == pytest.approx(exact, abs=1e-3 * z["fc_peak"].max())
    assert missed.sum() <= (2 if case == "slot" else 6)
    # closed form in the steady part (x from R + 0.2 mm, 5 tooth periods = 19 steps x 10)
    x = pos[1:, 0, 0]
    steady = np.flatnonzero(x > R + 2e-4)[:190]
    st, ex = {"slot": (0, math.pi), "up25": (0, math.acos(1 - ae / R)), "down25": (math.acos(ae / R - 1), math.pi)}[case]
    got = [q["fx_mean"][steady, 0].mean(), q["fy_mean"][steady, 0].mean()]
    assert got == pytest.approx(mean_force_on_workpiece(a, c, st, ex), rel=2e-3)


def test_partial_immersion_against_a_zmap_wall_and_second_pass_in_air():
    # pass 1: slot along +x at y = 0; lift, return above the part, plunge in the air;
    # pass 2: offset by 1.5 mm (50 % up-milling against the wall left by pass 1);
    # pass 3: pass 2 again = air cut
    a, c = 2e-3, 6e-5
    x0, x1, z_up = -R - 0.5e-3, 0.008 + R + 0.5e-3, 1e-3
    verts = [[x0, 0, -a], [x1, 0, -a], [x1, 0, z_up], [x0, -1.5e-3, z_up], [x0, -1.5e-3, -a], [x1, -1.5e-3, -a],
             [x1, -1.5e-3, z_up], [x0, -1.5e-3, z_up], [x0, -1.5e-3, -a], [x1, -1.5e-3, -a]]
    p = params(stock_x_max=0.008, stock_cell=1e-4)
    pos = along(verts, c / TOOTH_PERIOD * H)
    z = zmap_run(p, pos, OMEGA)
    q, _ = path_run(p, verts, pos, OMEGA)
    assert_modes_agree(z, q, worst=0.04)
    x, y, zz = pos[1:, 0, 0], pos[1:, 0, 1], pos[1:, 0, 2]
    second = np.flatnonzero((y < -1e-3) & (zz < -a + 1e-9) & (x > R + 2e-4) & (x < 0.008 - R))
    third_start = np.flatnonzero((y < -1e-3) & (zz > 0))[-1]
    assert q["fc_peak"][third_start:].max() == 0.0 and z["fc_peak"][third_start:].max() == 0.0
    # pass 2 mean: pass 1 left material at y < -R; the tool at y = -1.5 mm reaches y = -4.5 mm:
    # 1.5 mm (25 %) on the -y side, down-milling from acos(ae/R - 1) = 120 deg to 180 deg,
    # up to the Z-map wall bias (cell 0.1 mm, about 0.07 mm of ae; see the resolution study)
    exp = mean_force_on_workpiece(a, c, 2 * math.pi / 3, math.pi)
    seg = second[second < third_start][:190]
    got = [q["fx_mean"][seg, 0].mean(), q["fy_mean"][seg, 0].mean()]
    assert got == pytest.approx(exp, rel=0.1)


def test_contour_with_corners_matches_zmap_mode():
    # L-shaped slot with a 90 deg inside corner, then a 135 deg turn: engagement changes at the corners
    a, c = 1.5e-3, 8e-5
    verts = [[-R - 0.3e-3, 0.003, -a], [0.004, 0.003, -a], [0.004, 0.008, -a], [0.0005, 0.0115, -a]]
    p = params(stock_y_min=0.0, stock_y_max=0.012, stock_x_max=0.008)
    pos = along(verts, c / TOOTH_PERIOD * H)
    z = zmap_run(p, pos, OMEGA)
    q, _ = path_run(p, verts, pos, OMEGA)
    assert_modes_agree(z, q, worst=0.04)


def test_members_with_different_feeds_and_speeds_equal_separate_zmap_runs():
    a = 2e-3
    # straight, 2/3 immersion through a block corner (corners: see test_contour_with_corners; there the
    # Z-map mode's own near-field chords cut the corner differently for each feed, a Z-map artefact)
    verts = [[-R - 0.3e-3, 0.001, -a], [0.009, 0.001, -a]]
    p = params(stock_y_min=0.0, stock_x_max=0.006)
    feeds = np.array([4e-5, 6e-5, 8e-5])
    omegas = np.array([OMEGA, 0.8 * OMEGA, 1.3 * OMEGA])
    pos = along(verts, feeds * N * omegas / (2 * math.pi) * H)
    together, _ = path_run(p, verts, pos, omegas)
    for m in range(3):
        alone = zmap_run(p, pos[:, m:m + 1], omegas[m])
        single = {n: together[n][:, m:m + 1] for n in NAMES}
        assert_modes_agree(alone, single, worst=0.04)


def resolved(arcs, tol=1e-3):
    """Arcs (start, end) in rad, sorted, with gaps narrower than tol closed and arcs narrower than tol dropped."""
    out = []
    for lo, hi in sorted(arcs):
        if out and lo - out[-1][1] < tol:
            out[-1] = (out[-1][0], max(out[-1][1], hi))
        else:
            out.append((lo, hi))
    return [e for e in out if e[1] - e[0] > tol]


@pytest.mark.parametrize("offset", [0.0, 0.37])
def test_engagement_where_the_periphery_is_tangent_to_the_entry_and_exit_faces(offset):
    # slot along +x at y = 0 through the block 0 <= x <= 6 mm. Entering, a tool centre at d behind the
    # face x = 0 engages sin phi >= d / R: the arc opens around pi/2 as cos w = d / R (w: half-width);
    # leaving, the face x = 6 mm cuts the slot's [0, pi] where sin phi > d / R (d = 6 mm - x): a gap of
    # the same half-width opens around pi/2. w grows like the square root of the travel, so the table
    # (20 um stations; the tangency at a station, or 0.37 of a station after one) must not interpolate
    # it linearly (a linear rule was up to 0.13 rad off near these tangencies; now exact to 1e-5 rad).
    a = 2e-3
    x0 = -R - 0.3e-3 - offset * 2e-5
    verts = np.array([[x0, 0.0, -a], [0.0066, 0.0, -a]])
    table = EngagementTable.from_parameters(verts, params(stock_x_max=0.006))
    oa, ob, ot = np.empty(8), np.empty(8), np.empty(8)
    for face, x_tan in ((0.0, -R), (0.006, 0.006 - R)):
        for x in x_tan + np.linspace(-2e-5, 8e-5, 41):
            n = table_at(x - x0, table.spacing, table.count, table.alpha, table.beta, table.top, oa, ob, ot)
            lo = np.mod(oa[:n] + 1e-6, 2 * math.pi) - 1e-6  # the slot's start 0 may be stored as 2 pi - eps
            arcs = sorted(zip(lo, lo + ob[:n] - oa[:n]))
            d = abs(x - face)
            w = math.acos(min(d / R, 1.0))
            if face == 0.0:  # entering: [pi/2 - w, pi/2 + w], nothing before the tangency
                expected = [(math.pi / 2 - w, math.pi / 2 + w)] if x > x_tan else []
            else:  # leaving: the slot minus (pi/2 - w, pi/2 + w)
                expected = [(0.0, math.pi / 2 - w), (math.pi / 2 + w, math.pi)] if x > x_tan else [(0.0, math.pi)]
            arcs, expected = resolved(arcs), resolved(expected)
            assert len(arcs) == len(expected), (face, x)
            got, want = np.array(arcs).reshape(-1, 2), np.array(expected).reshape(-1, 2)
            assert got == pytest.approx(want, abs=1e-5), (face, x)


def test_table_read_remembering_its_station_pair_equals_the_plain_read_bit_for_bit():
    # table_at_from skips _pair_lean's structure and tangency tests for the station pair that last passed
    # them: on the tangency table above (pairs that interpolate plainly, tangencies, structure changes), reads
    # in path order, in random order and beyond both ends, with one remembered station throughout, must give
    # table_at's intervals exactly, and the remembered station must be one whose pair interpolates plainly
    a = 2e-3
    x0 = -R - 0.3e-3
    verts = np.array([[x0, 0.0, -a], [0.0066, 0.0, -a]])
    table = EngagementTable.from_parameters(verts, params(stock_x_max=0.006))
    args = (table.spacing, table.count, table.alpha, table.beta, table.top)
    length = float(table.vertex_s[-1])
    rng = np.random.default_rng(11)
    along = np.linspace(-1e-4, length + 1e-4, 4001)
    known = np.full(1, -1, dtype=np.int64)
    o1, o2 = [np.empty(8) for _ in range(3)], [np.empty(8) for _ in range(3)]
    used = set()
    for s in np.concatenate([along, rng.permutation(along), rng.uniform(-1e-4, length + 1e-4, 2000)]):
        n = table_at(float(s), *args, *o1)
        before = int(known[0])
        m = table_at_from(float(s), *args, *o2, known)
        assert m == n, s
        for p, q in zip(o1, o2):
            assert np.array_equal(p[:n], q[:n]), s
        if known[0] == before >= 0 and math.floor(s / table.spacing) == before:
            used.add(before)
    assert np.any(table.count[1:] != table.count[:-1])  # the table has structure changes to get wrong
    assert len(used) > 100  # the shortcut was taken, on many station pairs
    # a remembered pair interpolates plainly: same count on both stations (structure changes are not)
    for i in used:
        assert table.count[i] == table.count[i + 1]


# ---------------------------------------------------------------------------- path location and errors
def test_locate_is_monotone_on_a_reversal_and_prefers_the_earliest_tie():
    verts = np.array([[0.0, 0, 0], [0.01, 0, 0], [0.0, 0, 0]])
    vs = np.array([0.0, 0.01, 0.02])
    # going out: at x = 4 mm both legs are at distance 0; from s = 0 the first leg wins
    seg, s, d = locate(0.004, 0.0, 0.0, 0, 0.0, np.inf, verts, vs)
    assert (seg, s, d) == (0, pytest.approx(0.004), 0.0)
    # on the way back past the turn the cursor cannot go back: the second leg
    seg, s, d = locate(0.0098, 0.0, 0.0, 0, 0.00999, 1e-3, verts, vs)
    assert seg == 1 and s == pytest.approx(0.0102) and d == pytest.approx(0.0, abs=1e-15)
    # a lateral offset is projected (distance reported)
    seg, s, d = locate(0.005, 2e-6, 0.0, 0, 0.004, 1e-3, verts, vs)
    assert s == pytest.approx(0.005) and d == pytest.approx(2e-6)


def test_small_lateral_deviation_is_tolerated_and_a_far_member_is_an_error():
    a, c = 2e-3, 5e-5
    verts = [[-R - 0.5e-3, 0.0, -a], [0.004, 0.0, -a]]
    p = params()
    pos = along(verts, c / TOOTH_PERIOD * H)
    pos2 = np.repeat(pos, 2, axis=1)
    pos2[:, 1, 1] += 2e-6  # member 1 runs 2 um beside the path
    q, comp = path_run(p, verts, pos2, OMEGA)
    # a slot: a lateral offset of e changes the mean Fx by at most ~e/R of the load
    assert q["fx_mean"][:, 1] == pytest.approx(q["fx_mean"][:, 0], abs=1e-3 * q["fc_peak"].max())
    far = pos.copy()
    far[len(far) // 2:, 0, 1] += 1e-3  # jumps 1 mm sideways while in the material
    with pytest.raises(CuttingError, match="path_tolerance"):
        path_run(p, verts, far, OMEGA)


def test_table_file_round_trip_and_parameter_checks(tmp_path):
    a = 2e-3
    verts = np.array([[-R - 0.5e-3, 0.0, -a], [0.002, 0.0, -a]])
    p = params()
    table = build_engagement_table(verts, 2 * R, [0, -0.01, -0.01], [0.012, 0.01, 0.0], 1e-4)
    f = tmp_path / "table.npz"
    table.save(f)
    back = EngagementTable.load(f)
    assert np.array_equal(back.alpha, table.alpha) and back.spacing == table.spacing
    # a slot station: one interval, the front half [0, pi] within the rim tolerance, top = stock top
    i = table.stations - 1
    assert table.count[i] == 1
    assert np.mod(table.alpha[i, 0] + 1e-6, 2 * math.pi) == pytest.approx(1e-6, abs=1e-6)
    assert table.beta[i, 0] - table.alpha[i, 0] == pytest.approx(math.pi, abs=1e-6)
    assert table.top[i, 0] == 0.0
    comp = PathCuttingLoad("cut", engagement_table=str(f), **p)
    comp.set("x_position", verts[0, 0])
    comp.set("z_position", -a)
    comp.setup(0.0)
    with pytest.raises(CuttingError, match="tool_diameter"):
        bad = PathCuttingLoad("cut", **params(tool_diameter=8e-3))
        bad.attach_table(table)
        bad.setup(0.0)
    with pytest.raises(CuttingError, match="stock_x_max"):
        bad = PathCuttingLoad("cut", **params(stock_x_max=0.02))
        bad.attach_table(table)
        bad.setup(0.0)
    with pytest.raises(CuttingError, match="no engagement table"):
        PathCuttingLoad("cut", **p).setup(0.0)
    with pytest.raises(CuttingError, match="shape"):
        build_engagement_table(np.zeros((3, 2)), 2 * R, [0, 0, 0], [1, 1, 1], 1e-4)


def test_table_built_with_the_compiled_commit_equals_the_numpy_commit(monkeypatch):
    """The table's stations commit the swept material with the component's compiled commit
    (``table.use_compiled_commit``); the numpy path (advance, pop_ready, remove_sweep) gives the same
    table bit for bit: a plunge to 1.5 mm, a slot in +X, a 90 deg turn into +Y and a second pass back
    over the slot (where the committed Z-map, not the near field, holds the removed material)."""
    turn = [[0.004 + R * math.sin(t), 0.003 - R * math.cos(t), -1.5e-3] for t in np.linspace(0.0, math.pi / 2, 9)]
    verts = np.array([[0.002, 0.0, 1e-3], [0.002, 0.0, -1.5e-3], [0.004, 0.0, -1.5e-3], *turn,
                      [0.004 + R, 0.006, -1.5e-3], [0.004 + R, 0.006, -0.5e-3], [0.001, 0.0, -0.5e-3]])
    built = {}
    for compiled in (True, False):
        monkeypatch.setattr(table_module, "use_compiled_commit", compiled)
        built[compiled] = build_engagement_table(verts, 2 * R, [0, -0.01, -0.01], [0.012, 0.01, 0.0], 1e-4)
    a, b = built[True], built[False]
    assert a.count.sum() > 0 and a.count[-1] > 0  # it cuts, also on the pass back over the slot
    for name in ("count", "alpha", "beta", "top", "axial_area", "axial_span"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
