"""Ground-truth cutting forces with hidden cutting-process effects, implemented independently of the twin.

The cutting diagnosis is proven on recordings whose force physics it does
not share. Only the *engagement geometry* is the twin's (which angles of the
cutter periphery are in material, and how high the material stands there:
the :class:`fmus_src.cutting.table.EngagementTable` of the case's program);
the forces are summed here from the equations, on a fine time grid
(:func:`_cut_kernel`):

* **tooth by tooth, in axial slices** of :data:`SLICE_M`: a slice at height
  ``z`` above the tool tip sits at ``phi = theta + j p - z tan(helix) / R``
  (helix lag), is in the cut when ``phi`` lies in an engagement interval
  whose material top is above the slice (partial slices by their overlap;
  a helical slice spans ``SLICE_M tan(helix) / R`` of angle and cuts with
  the fraction of it inside the interval, :func:`_slice_overlap`);
* **chip thickness from the path**: ``h = (c(t) - c(t - T)) . n`` with the
  tool-centre positions ``c`` one tooth period ``T`` apart (not the twin's
  velocity x period), ``n = (sin phi, cos phi)``;
* **runout**: tooth ``j`` stands out by ``r_j = rho cos(j p - lambda)``; the
  material it meets was left by tooth ``j + i`` ``i`` periods earlier (teeth
  sit at ``theta + j p`` and the spindle angle grows), and it cuts the lowest
  of those surfaces: ``h_j = min_i [(c(t) - c(t - i T)) . n + r_j - r_(j+i)]``,
  ``i = 1..N`` (a tooth that stands back leaves the older surface in place;
  ``N`` = flutes, with the tool mode on :data:`CHATTER_PASSES`);
  its torque arm is ``R + r_j``;
* **edge forces**: ``dFt = (Kt h + Kte) dz``, ``dFr = (Kr h + Kre) dz``
  while a slice has a positive chip;
* **tool deflection** (quasi-static, per tooth, the effect as the twin
  defines it): a tooth's radial force ``Fr`` pushes the tool off the
  surface by ``Fr / k``, which removes that much chip from every slice of
  the tooth; the fixed point ``Delta = sum (Kr (h0 - Delta)+ + Kre) w / k``
  is iterated over the slices still in contact (one step without helix:
  ``h = h0 / (1 + Kr d / k)`` with edge forces aside);
* **tool wear**: every coefficient grows as ``1 + rate t_cut`` with the
  engaged cutting time ``t_cut``;
* **spindle droop**: the spindle turns at ``omega_cmd - droop T_f`` with the
  cutting torque through a first-order speed-loop lag of
  :data:`DROOP_LAG_S`; the angle integrates that speed;
* **chatter**: an isotropic tool mode in x and y (frequency, damping ratio,
  stiffness) driven by the force on the tool, integrated in
  :data:`MODE_SUBSTEPS` substeps per fine step, with the regenerative chip
  ``(u(t) - u(t - T)) . n`` (the tool displacement ``u`` now against when
  the surface was left; Altintas ch. 3), taken at the middle of each fine
  step over which the force is held; beyond the stability lobe the
  vibration grows until teeth leave the cut and the next ones cut the
  lowest surface left by any of the last :data:`CHATTER_PASSES` teeth.

The tool-centre path comes from the independent truth servo
(:func:`.truth.simulate_truth`) run on the twin's NC commands, once without
and once with the cutting force as the drives' disturbance (one fixed-point
pass: the second changes the positions by well under a micrometre).
:func:`record_cutting` plays the loggers: a dynamometer at 5 kHz without an
anti-alias filter (instantaneous samples: the twin's ``fx``, ``fy`` outputs
are instantaneous too), Gaussian noise, and the CNC logger of
:mod:`.truth` at 1.7 ms for positions, currents and the spindle speed (1 rpm
resolution), one clock for both with a seeded offset.

Effects use the vocabulary of ``shared/spec/diagnosis.md``, e.g.
``{"runout": {"eccentricity_um": 8.0, "phase_deg": 40.0}}``; the chatter mode
additionally takes ``damping_ratio`` and ``stiffness_N_per_um`` (the spec
reports only ``frequency_Hz``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Mapping

import numpy as np

from fmus_src.cutting import path_kernel as pk
from fmus_src.cutting.table import EngagementTable
from fmus_src.jit import njit
from fmus_src.jit_cache import guard_cache

from ..machine import Machine
from ..recording import Recording
from .errors import DiagnosisError

#: Fine time step of the truth cutting simulation, s.
FINE_STEP_S = 20e-6
#: Axial slice thickness, m.
SLICE_M = 50e-6
#: Speed-loop lag of the spindle droop, s.
DROOP_LAG_S = 1e-3
#: Substeps of the chatter mode per fine step.
MODE_SUBSTEPS = 4
#: Fixed-point steps of the deflection (the active slices change at most a few times).
DEFLECTION_STEPS = 8
#: Surfaces a tooth may cut with the tool mode on (tooth periods back; :func:`surfaces_remembered`): one
#: revolution of the 3-flute tool plus the two teeth skipped at the chatter limit cycle. Measured on the
#: chatter case (1150 Hz, 3 %, 30 N/um, 2 mm slot) with ``passes`` = 9: teeth cut surfaces 1..5 periods
#: back, never 6+; limit cycle 68.3 / 59.4 / 57.6 / 57.6 N with 3 / 4 / 5 / 9 surfaces. The twin's
#: ``fmus_src.cutting.effect_model.MAX_PASSES`` is the same number (a shared modelling choice, not code).
CHATTER_PASSES = 5
#: Maximum number of engagement intervals the kernel reads per station.
TWO_PI = 2.0 * math.pi

# packed parameters
_Q = ("radius", "flutes", "kt", "kr", "kte", "kre", "rho", "lam", "helix", "stiffness", "wear", "droop",
      "fn", "zeta", "kc", "theta0", "passes")

#: Hidden cutting effect parameter (spec name) -> (packed name, factor to SI).
CUTTING_PARAMETERS: dict[tuple[str, str], tuple[str, float]] = {
    ("runout", "eccentricity_um"): ("rho", 1e-6),
    ("runout", "phase_deg"): ("lam", math.pi / 180.0),
    ("helix_angle", "helix_deg"): ("helix", math.pi / 180.0),
    ("edge_force", "kte_N_per_mm"): ("kte", 1e3),
    ("edge_force", "kre_N_per_mm"): ("kre", 1e3),
    ("tool_deflection", "stiffness_N_per_um"): ("stiffness", 1e6),
    ("tool_wear", "rate_percent_per_min"): ("wear", 1.0 / 100.0 / 60.0),
    ("spindle_droop", "rpm_per_Nm"): ("droop", 2.0 * math.pi / 60.0),
    ("chatter", "frequency_Hz"): ("fn", 1.0),
    ("chatter", "damping_ratio"): ("zeta", 1.0),
    ("chatter", "stiffness_N_per_um"): ("kc", 1e6),
    ("kt_mismatch", "factor"): ("kt", 1.0),   # multiplies the machine's Kt (a coefficient error, not an effect)
}


@njit
def surfaces_remembered(flutes: int, chatter: bool, override: int) -> int:
    """Surfaces a tooth may cut: those left ``1..N`` tooth periods back (``N`` returned).

    Without a tool mode one revolution (``flutes``): runout never makes an older surface the lowest.
    With it, :data:`CHATTER_PASSES` (a tooth that jumped out of the cut leaves the older surface in
    place; the twin's ``fmus_src.cutting.effect_model.MAX_PASSES`` is the same number, chosen
    independently). ``override > 0`` replaces both (measurements of how far teeth look back).
    """
    if override > 0:
        return override
    if chatter:
        return max(CHATTER_PASSES, 1)
    return flutes


@njit
def _interp_row(arr: np.ndarray, x: float) -> float:
    """``arr`` at fractional index ``x`` (linear, clamped)."""
    n = arr.shape[0]
    if x <= 0.0:
        return arr[0]
    i0 = int(math.floor(x))
    if i0 >= n - 1:
        return arr[n - 1]
    f = x - i0
    return arr[i0] * (1.0 - f) + arr[i0 + 1] * f


@njit
def _slice_overlap(phi: float, span: float, ia: np.ndarray, ib: np.ndarray, it: np.ndarray, cm: int,
                   bottom: float, z_lo: float, slice_m: float) -> tuple[float, float]:
    """Cutting width of a helical slice and the angle of its part in material.

    The slice ``[z_lo, z_lo + slice_m)`` of a helical flute covers the angles
    ``[phi - span / 2, phi + span / 2]``; the fraction of them inside interval
    ``c`` cuts with that interval's material height. Returns ``(w, phi_c)``:
    the axial width [m] times the fraction in material, summed over the
    (disjoint) intervals, and the weighted middle of those parts [rad].
    Without this a slice enters the cut all at once, a jump of one slice's
    force (2.6 N for 50 um at a 1 mm radial entry, 0.05 mm/tooth, A6061).
    """
    lo = phi - 0.5 * span
    hi = phi + 0.5 * span
    w = 0.0
    moment = 0.0
    for c in range(cm):
        wc = min(max(it[c] - bottom - z_lo, 0.0), slice_m)
        if wc <= 0.0:
            continue
        for shift in (-TWO_PI, 0.0, TWO_PI):
            a = max(lo, ia[c] + shift)
            b = min(hi, ib[c] + shift)
            if b > a:
                part = wc * (b - a) / span
                w += part
                moment += part * 0.5 * (a + b)
    if w <= 0.0:
        return 0.0, phi
    return w, moment / w


@njit
def _cut_kernel(pos: np.ndarray, omega_cmd: np.ndarray, dt: float, q: np.ndarray, verts: np.ndarray,
                vs: np.ndarray, ds: float, count: np.ndarray, alpha: np.ndarray, beta: np.ndarray,
                top: np.ndarray, z_floor: float, slice_m: float, out: np.ndarray) -> None:
    """Truth cutting forces on the fine grid (see the module docstring).

    Parameters
    ----------
    pos : ndarray, shape (n, 3)
        Tool-tip position (work coordinates) at ``t0 + k dt``, m.
    omega_cmd : ndarray, shape (n,)
        Commanded (ramped) spindle speed, rad/s.
    q : ndarray
        Packed parameters (:data:`_Q`).
    out : ndarray, shape (n, 7)
        Written: force on the **workpiece** x, y [N], torque [N.m], actual spindle speed [rad/s],
        spindle angle [rad], 1 where a tooth cuts, the most tooth periods back of a surface cut.
    """
    n = pos.shape[0]
    radius, flutes, kt, kr, kte, kre = q[0], int(q[1]), q[2], q[3], q[4], q[5]
    rho, lam, helix, stiff, wear, droop = q[6], q[7], q[8], q[9], q[10], q[11]
    fn, zeta, kc, theta = q[12], q[13], q[14], q[15]
    chat = fn > 0.0 and kc > 0.0
    npass = surfaces_remembered(flutes, chat, int(q[16]))
    pitch = TWO_PI / flutes
    tan_b = math.tan(helix)
    span = slice_m * abs(tan_b) / radius  # spindle angle swept by one helical slice
    kmax = alpha.shape[1]
    ia = np.empty(kmax)
    ib = np.empty(kmax)
    it = np.empty(kmax)
    roff = np.empty(flutes)
    for j in range(flutes):
        roff[j] = rho * math.cos(j * pitch - lam)
    # feed and tool vibration over the last 1..npass tooth periods
    fpx = np.zeros(npass + 1)
    fpy = np.zeros(npass + 1)
    max_sl = int(math.ceil(0.05 / slice_m))
    sl_h0 = np.empty(max_sl)
    sl_w = np.empty(max_sl)
    sl_s = np.empty(max_sl)
    sl_c = np.empty(max_sl)
    sl_p = np.zeros(max_sl, dtype=np.int64)
    # chatter mode (m = kc / wn^2, c = 2 zeta sqrt(kc m))
    wn = TWO_PI * fn
    mass = kc / (wn * wn) if chat else 1.0
    damp = 2.0 * zeta * math.sqrt(kc * mass) if chat else 0.0
    ux = np.zeros(n)
    uy = np.zeros(n)
    vx = 0.0
    vy = 0.0
    seg = 0
    s_cur = 0.0
    t_cut = 0.0
    torque_f = 0.0
    for k in range(n):
        cx, cy, cz = pos[k, 0], pos[k, 1], pos[k, 2]
        om = omega_cmd[k] - droop * torque_f
        if om < 0.0:
            om = 0.0
        theta += om * dt
        # global search at the start, then forward from the cursor
        seg, s_cur, dist = pk.locate(cx, cy, cz, seg, s_cur, math.inf if k == 0 else 1e-3, verts, vs)
        cm = pk.table_at(s_cur, ds, count, alpha, beta, top, ia, ib, it)
        bottom = max(cz, z_floor)
        u_now_x = ux[k - 1] if k > 0 else 0.0
        u_now_y = uy[k - 1] if k > 0 else 0.0
        # the force is held over (t_k-1, t_k]: its dynamic chip is taken at the middle, u(t_k-1/2) - u(t_k-1/2 - iT)
        # (u at the start and the delayed u at the end put a phase error of one step, 8 deg at 1150 Hz and
        # 20 us, into the regenerative loop: limit cycle 77 N against 70.6 N converged at 5 us)
        u_mid_x = u_now_x + 0.5 * dt * vx
        u_mid_y = u_now_y + 0.5 * dt * vy
        # the surfaces left 1..npass tooth periods ago: tool-centre and vibration displacement since then
        back = TWO_PI / (flutes * om) / dt if om > 1e-6 else 0.0
        for i in range(1, npass + 1):
            kb = k - i * back
            # the tool is now at c + u, the surface was left at c(t - iT) + u(t - iT): a tool pushed off
            # the material (u . n < 0, the radial force's direction) takes a thinner chip
            fpx[i] = cx - _interp_row(pos[:, 0], kb) + u_mid_x - _interp_row(ux, kb - 0.5)
            fpy[i] = cy - _interp_row(pos[:, 1], kb) + u_mid_y - _interp_row(uy, kb - 0.5)
        wf = 1.0 + wear * t_cut
        depth_max = 0.0
        for c in range(cm):
            if it[c] - bottom > depth_max:
                depth_max = it[c] - bottom
        fx_t = 0.0
        fy_t = 0.0
        torque = 0.0
        cutting = False
        looked = 0
        if cm > 0 and depth_max > 0.0:
            n_sl = min(int(math.ceil(depth_max / slice_m - 1e-9)), max_sl)
            for j in range(flutes):
                arm = radius + roff[j]
                ns = 0
                for i in range(n_sl):
                    z_lo = i * slice_m
                    zc = z_lo + 0.5 * slice_m
                    phi = theta + j * pitch - zc * tan_b / radius
                    phi = phi - math.floor(phi / TWO_PI) * TWO_PI
                    if span > 0.0:
                        # a helical slice sweeps [phi - span/2, phi + span/2]: the part of it inside each
                        # interval cuts (a slice across an entry is partly in the cut), at that part's middle
                        w, phi = _slice_overlap(phi, span, ia, ib, it, cm, bottom, z_lo, slice_m)
                    else:
                        d = 0.0
                        for c in range(cm):
                            if (ia[c] <= phi <= ib[c]) or (phi + TWO_PI <= ib[c]):
                                if it[c] - bottom > d:
                                    d = it[c] - bottom
                        w = min(max(d - z_lo, 0.0), slice_m)
                    if w <= 0.0:
                        continue
                    sp = math.sin(phi)
                    cp = math.cos(phi)
                    # the lowest of the surfaces left by the teeth 1..npass periods back (multiple passes)
                    h0 = math.inf
                    p0 = 0
                    for p in range(1, npass + 1):
                        hp = fpx[p] * sp + fpy[p] * cp + roff[j] - roff[(j + p) % flutes]
                        if hp < h0:
                            h0 = hp
                            p0 = p
                    sl_p[ns] = p0
                    sl_h0[ns] = h0
                    sl_w[ns] = w
                    sl_s[ns] = sp
                    sl_c[ns] = cp
                    ns += 1
                # static deflection of this tooth: its radial force pushes the tool off the surface by
                # Fr / k, removing that much chip from every slice: Delta = sum (Kr (h0 - Delta) + Kre) w / k
                delta = 0.0
                if stiff > 0.0:
                    for _ in range(DEFLECTION_STEPS):
                        num = 0.0
                        den = stiff
                        for i in range(ns):
                            if sl_h0[i] - delta > 0.0:
                                num += (wf * kr * sl_h0[i] + wf * kre) * sl_w[i]
                                den += wf * kr * sl_w[i]
                        new = num / den
                        if abs(new - delta) < 1e-15:
                            delta = new
                            break
                        delta = new
                for i in range(ns):
                    h = sl_h0[i] - delta
                    if h <= 0.0:
                        continue
                    cutting = True
                    if sl_p[i] > looked:
                        looked = sl_p[i]
                    dft = (wf * kt * h + wf * kte) * sl_w[i]
                    dfr = (wf * kr * h + wf * kre) * sl_w[i]
                    fx_t += -dft * sl_c[i] - dfr * sl_s[i]
                    fy_t += dft * sl_s[i] - dfr * sl_c[i]
                    torque += dft * arm
        if cutting:
            t_cut += dt
        torque_f += (torque - torque_f) * dt / DROOP_LAG_S
        # chatter mode: m u'' + c u' + kc u = F_tool (force on the tool)
        if chat:
            x = u_now_x
            y = u_now_y
            h_m = dt / MODE_SUBSTEPS
            for _ in range(MODE_SUBSTEPS):
                vx += h_m * (fx_t - damp * vx - kc * x) / mass
                vy += h_m * (fy_t - damp * vy - kc * y) / mass
                x += h_m * vx
                y += h_m * vy
            ux[k] = x
            uy[k] = y
        out[k, 0] = -fx_t
        out[k, 1] = -fy_t
        out[k, 2] = torque
        out[k, 3] = om
        out[k, 4] = theta
        out[k, 5] = 1.0 if cutting else 0.0
        out[k, 6] = looked


# the cached kernel links path_kernel's locate and table_at: recompile it when that module changes (numba keys
# its cache on this file only; a stale table_at opened a face's engagement 2 um before the tool touched it)
guard_cache(_cut_kernel, pk)


def cutting_parameters_packed(machine: Machine, material: str, diameter_m: float, flutes: int,
                              effects: Mapping[str, Mapping[str, float]] | None, theta0: float) -> np.ndarray:
    """Packed truth parameters: the machine's Kt, Ke plus the hidden cutting effects (spec units)."""
    mat = machine.si(f"material.{material}")
    values = dict.fromkeys(_Q, 0.0)
    values.update(radius=0.5 * diameter_m, flutes=float(flutes), kt=float(mat["kt"]), theta0=theta0)
    ke = float(mat["ke"])
    for effect, params in (effects or {}).items():
        for name, value in params.items():
            key = (effect, name)
            if key not in CUTTING_PARAMETERS:
                raise DiagnosisError(f"unknown truth cutting-effect parameter {effect}.{name}; expected one of "
                                     f"{sorted(f'{e}.{p}' for e, p in CUTTING_PARAMETERS)}")
            packed, factor = CUTTING_PARAMETERS[key]
            if packed == "kt":
                values["kt"] *= float(value)
            else:
                values[packed] = float(value) * factor
    if values["fn"] > 0.0 and values["kc"] <= 0.0:
        raise DiagnosisError("truth chatter needs stiffness_N_per_um > 0 besides frequency_Hz")
    if values["fn"] > 0.0 and values["zeta"] <= 0.0:
        values["zeta"] = 0.03
    values["kr"] = ke * values["kt"]
    return np.array([values[k] for k in _Q], dtype=float)


@dataclass
class CuttingRun:
    """Truth cutting signals on the fine grid (program clock).

    Attributes
    ----------
    t : ndarray, shape (n,)
        Fine-grid times, s.
    fx, fy : ndarray
        Force on the workpiece, N.
    torque : ndarray
        Cutting torque, N.m.
    omega : ndarray
        Actual spindle speed, rad/s.
    theta : ndarray
        Spindle angle of tooth 0, rad (unwrapped).
    cutting : ndarray of bool
        A tooth cuts.
    lookback : ndarray of int
        Most tooth periods back of a surface any slice cuts in that instant (1 = the previous tooth's;
        0 in the air): how far the multiple regeneration reaches.
    """

    t: np.ndarray
    fx: np.ndarray
    fy: np.ndarray
    torque: np.ndarray
    omega: np.ndarray
    theta: np.ndarray
    cutting: np.ndarray
    lookback: np.ndarray


def simulate_cutting(table: EngagementTable, t: np.ndarray, position: np.ndarray, omega_cmd: np.ndarray,
                     packed: np.ndarray) -> CuttingRun:
    """Run :func:`_cut_kernel` on a fine grid.

    Parameters
    ----------
    table : EngagementTable
        Engagement along the program's path (the twin's geometry).
    t : ndarray, shape (n,)
        Uniform fine grid, s.
    position : ndarray, shape (n, 3)
        Tool-tip position at ``t``, m.
    omega_cmd : ndarray, shape (n,)
        Commanded spindle speed at ``t``, rad/s.
    packed : ndarray
        :func:`cutting_parameters_packed`.
    """
    dt = float(t[1] - t[0])
    out = np.zeros((t.size, 7))
    _cut_kernel(np.ascontiguousarray(position, dtype=float), np.ascontiguousarray(omega_cmd, dtype=float), dt,
                packed, table.vertices, table.vertex_s, table.spacing, table.count, table.alpha, table.beta,
                table.top, table.z_floor, SLICE_M, out)
    return CuttingRun(t, out[:, 0], out[:, 1], out[:, 2], out[:, 3], out[:, 4], out[:, 5] > 0.5,
                      out[:, 6].astype(np.int64))


@dataclass(frozen=True)
class Dynamometer:
    """The force logger (and the spindle-speed resolution of the CNC logger).

    Attributes
    ----------
    period_s : float
        Force sample period, s (no anti-alias filter: instantaneous samples).
    force_noise_N : float
        Gaussian noise of fx, fy, N.
    spindle_noise_rpm, spindle_quantum_rpm : float
        Noise and resolution of the logged actual spindle speed, rpm.
    hum_N, hum_Hz : float
        An additive sinusoid on ``fx_N`` (mains hum; a phenomenon outside the effect table), N and Hz.
    """

    period_s: float = 0.2e-3
    force_noise_N: float = 1.0
    spindle_noise_rpm: float = 0.5
    spindle_quantum_rpm: float = 1.0
    hum_N: float = 0.0
    hum_Hz: float = 50.0


@dataclass
class CuttingScenario:
    """Hidden truth of a cutting case: drive effects per axis and cutting effects."""

    cutting: dict[str, dict[str, float]] = field(default_factory=dict)
    drives: dict[str, dict[str, dict[str, float]]] = field(default_factory=dict)


def merge_recordings(cnc: Recording, force: Mapping[str, np.ndarray]) -> Recording:
    """One recording from the CNC logger's rows and the dynamometer's rows (same clock), sorted by time.

    Cells a logger did not measure are empty (NaN), as recording.md allows.
    """
    t_cnc = np.asarray(cnc.t, float)
    t_f = np.asarray(force["t_s"], float)
    t = np.concatenate([t_cnc, t_f])
    order = np.argsort(t, kind="stable")
    channels: dict[str, np.ndarray] = {"t_s": t[order]}
    n_c, n_f = t_cnc.size, t_f.size
    for name in cnc.channels:
        if name == "t_s":
            continue
        channels[name] = np.concatenate([np.asarray(cnc[name], float), np.full(n_f, np.nan)])[order]
    for name, values in force.items():
        if name == "t_s":
            continue
        channels[name] = np.concatenate([np.full(n_c, np.nan), np.asarray(values, float)])[order]
    return Recording.from_channels(channels, source="<truth cutting recording>")


def sample_forces(run: CuttingRun, t_prog: np.ndarray, dyn: Dynamometer, rng: np.random.Generator
                  ) -> dict[str, np.ndarray]:
    """Dynamometer samples at program times ``t_prog``: ``fx_N``, ``fy_N``, ``fc_N`` (noisy, instantaneous)."""
    fx = np.interp(t_prog, run.t, run.fx) + rng.normal(0.0, dyn.force_noise_N, t_prog.size)
    fy = np.interp(t_prog, run.t, run.fy) + rng.normal(0.0, dyn.force_noise_N, t_prog.size)
    if dyn.hum_N:
        fx = fx + dyn.hum_N * np.sin(2.0 * math.pi * dyn.hum_Hz * t_prog + 0.3)
    return {"fx_N": fx, "fy_N": fy, "fc_N": np.hypot(fx, fy)}


def spindle_channel(run: CuttingRun, t_prog: np.ndarray, dyn: Dynamometer, rng: np.random.Generator) -> np.ndarray:
    """Logged actual spindle speed [rpm] at program times (noise, resolution)."""
    rpm = np.interp(t_prog, run.t, run.omega) * 60.0 / TWO_PI
    rpm = rpm + rng.normal(0.0, dyn.spindle_noise_rpm, rpm.size)
    q = dyn.spindle_quantum_rpm
    return np.round(rpm / q) * q if q > 0 else rpm


def fine_grid(t0: float, t1: float, dt: float = FINE_STEP_S) -> np.ndarray:
    """Uniform grid ``t0 + k dt`` up to ``t1``."""
    n = int(math.floor((t1 - t0) / dt + 1e-9)) + 1
    return t0 + dt * np.arange(n)


def tick_mean(t_fine: np.ndarray, values: np.ndarray, t_ticks: np.ndarray, tv: float) -> np.ndarray:
    """Mean of ``values`` over each tick ``[t_k - tv, t_k]`` (a drive's disturbance over a servo tick)."""
    cum = np.concatenate([[0.0], np.cumsum(values[:-1] * np.diff(t_fine))])
    c1 = np.interp(t_ticks, t_fine, cum)
    c0 = np.interp(t_ticks - tv, t_fine, cum)
    return (c1 - c0) / tv


def replace_dyn(dyn: Dynamometer, **changes: float) -> Dynamometer:
    """A copy of ``dyn`` with ``changes``."""
    return replace(dyn, **changes)
