"""Z-map resolution study: force accuracy against the closed form, and cost.

Cases (6 mm 2-flute end mill, ``Kt = 1.23e9 N/m2``, ``Ke = 0.5``, 2 mm axial
depth, 0.05 mm feed per tooth, 7895 rpm (tooth period 3.8 ms), feed along +x):

* ``slot`` — full slot in fresh stock (engagement from the near field only);
* ``50% up`` / ``50% down`` / ``25% up`` / ``25% down`` — a first slot is cut
  and committed to the Z-map, then a second pass offset sideways by the
  radial width of cut ``ae``; the material wall the tool meets is the Z-map
  wall of the first slot, so the result measures the Z-map resolution.

Each case is repeated with the path offset by a random fraction of a cell
(seeded), so that the error covers the grid alignment. The reference is the
closed-form mean force (:func:`.force.average_forces_on_tool`).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from .component import CuttingLoad
from .force import average_forces_on_tool

KT = 1.23e9
KE = 0.5
DIAMETER = 6e-3
FLUTES = 2
DEPTH = 2e-3
FEED_PER_TOOTH = 5e-5
TOOTH_PERIOD = 3.8e-3
STEP = 1e-3
#: Reference stock footprint for the memory figure, m (100 mm x 100 mm).
REFERENCE_FOOTPRINT = (0.1, 0.1)

CASES: dict[str, tuple[float, int]] = {
    # name: (radial immersion ae / D, +1 up-milling side (+y), -1 down-milling side (-y), 0 slot)
    "slot": (1.0, 0),
    "50% up": (0.5, 1),
    "50% down": (0.5, -1),
    "25% up": (0.25, 1),
    "25% down": (0.25, -1),
}


@dataclass(frozen=True)
class StudyRow:
    """One line of the resolution study.

    Attributes
    ----------
    cell : float
        Z-map cell edge, m.
    case : str
        Key of :data:`CASES`.
    max_error : float
        Largest relative error of the mean force vector over the repeats, 1.
    mean_error : float
        Mean relative error over the repeats, 1.
    time_per_step : float
        CPU time of one 1 ms communication step, s (batch of all cases and repeats).
    members : int
        Batch size of that timing.
    memory_reference : int
        Bytes of one member's Z-map for the 100 mm x 100 mm reference stock.
    """

    cell: float
    case: str
    max_error: float
    mean_error: float
    time_per_step: float
    members: int
    memory_reference: int


def engagement_angles(ae_fraction: float, side: int) -> tuple[float, float]:
    """Entry and exit angles for a radial immersion (feed along +x), rad.

    ``side = +1``: material on the +y side (up-milling, ``phi`` from 0);
    ``side = -1``: on the -y side (down-milling, ``phi`` up to pi); ``0``: slot.
    """
    if side == 0:
        return 0.0, math.pi
    if side > 0:
        return 0.0, math.acos(1.0 - 2.0 * ae_fraction)
    return math.acos(2.0 * ae_fraction - 1.0), math.pi


def reference_force(case: str) -> np.ndarray:
    """Closed-form mean force on the **workpiece** for a case, N (shape (2,))."""
    fx, fy = average_forces_on_tool(KT, KE, DEPTH, FEED_PER_TOOTH, FLUTES, *engagement_angles(*CASES[case]))
    return -np.array([fx, fy])


def _polyline(points: np.ndarray, steps: list[int]) -> np.ndarray:
    """Positions at the end of each step along per-member polylines.

    Parameters
    ----------
    points : ndarray, shape (B, P, 3)
    steps : list of int, length P - 1 (steps per segment, shared by the batch)

    Returns
    -------
    ndarray, shape (sum(steps), B, 3)
    """
    out = []
    for i, m in enumerate(steps):
        s = (np.arange(1, m + 1) / m)[:, None, None]
        out.append(points[None, :, i] + s * (points[None, :, i + 1] - points[None, :, i]))
    return np.concatenate(out, axis=0)


def run_cases(cell: float, cases: list[str], repeats: int, seed: int = 0,
              angle_steps: int = 36) -> tuple[dict[str, np.ndarray], float, int]:
    """Simulate all cases x repeats in one batch; return mean workpiece forces.

    Returns
    -------
    forces : dict
        Case → array (repeats, 2) of mean (Fx, Fy) on the workpiece, N.
    time_per_step : float
        CPU time per communication step over the measured pass, s.
    members : int
        Batch size.
    """
    rng = np.random.default_rng(seed)
    R = 0.5 * DIAMETER
    length = 0.010
    B = len(cases) * repeats
    offset = rng.uniform(0.0, cell, size=B)
    offset_x = rng.uniform(0.0, cell, size=B)
    side = np.array([CASES[c][1] for c in cases for _ in range(repeats)], dtype=float)
    ae = np.array([CASES[c][0] for c in cases for _ in range(repeats)])
    omega = 2.0 * math.pi / (FLUTES * TOOTH_PERIOD)
    feed = FEED_PER_TOOTH / TOOTH_PERIOD
    comp = CuttingLoad(
        batch=B, tool_diameter=DIAMETER, flutes=FLUTES, kt=KT, ke=KE,
        stock_x_min=-offset_x, stock_x_max=length - offset_x, stock_y_min=-0.01, stock_y_max=0.01,
        stock_z_min=-0.01, stock_z_max=0.0, stock_cell=cell, angle_steps_per_tooth=angle_steps,
    )
    x0 = -R - 0.5e-3
    x1 = length + R + 0.5e-3
    safe = 2e-3
    y_second = offset + side * ae * DIAMETER  # slot: side 0 -> second pass on the first path... see below
    slot = side == 0
    # first pass: the slot that makes the wall (skipped for the slot case: it stays in air above the stock)
    z_first = np.where(slot, safe, -DEPTH)

    def pts(*rows: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
        return np.stack([np.stack(np.broadcast_arrays(x, y, z), axis=1) for x, y, z in rows], axis=1)

    first = pts((x0, offset, safe), (x0, offset, z_first), (x1, offset, z_first), (x1, offset, safe),
                (x0, offset, safe), (x0, y_second, safe), (x0, y_second, -DEPTH))
    fast = max(1, int(round((x1 - x0) / (20 * feed * STEP))))
    prep = _polyline(first, [5, fast, 5, fast, 5, 5])
    comp.set("x_position", first[:, 0, 0])
    comp.set("y_position", first[:, 0, 1])
    comp.set("z_position", first[:, 0, 2])
    comp.set("spindle_speed", omega)
    comp.setup(0.0)
    k = 0
    for p in prep:
        comp.set("x_position", p[:, 0])
        comp.set("y_position", p[:, 1])
        comp.set("z_position", p[:, 2])
        comp.do_step(k * STEP, STEP)
        k += 1
    # measured pass: from x0 to x = R + 0.2 mm in steady cut, then 10 tooth periods (38 steps x 5)
    x_start = R + 0.2e-3
    n_in = int(math.ceil((x_start - x0) / (feed * STEP)))
    n_meas = 190
    xs = x0 + feed * STEP * np.arange(1, n_in + n_meas + 1)
    sums = np.zeros((B, 2))
    t_meas = 0.0
    for i, x in enumerate(xs):
        comp.set("x_position", x)
        comp.set("y_position", y_second)
        comp.set("z_position", -DEPTH)
        t0 = time.process_time()
        comp.do_step(k * STEP, STEP)
        t_meas += time.process_time() - t0
        k += 1
        if i >= n_in:
            sums[:, 0] += comp.get("fx_mean")
            sums[:, 1] += comp.get("fy_mean")
    means = sums / n_meas
    forces = {c: means[i * repeats:(i + 1) * repeats] for i, c in enumerate(cases)}
    return forces, t_meas / len(xs), B


def resolution_study(
    cells: tuple[float, ...] = (4e-4, 2e-4, 1e-4, 5e-5),
    cases: tuple[str, ...] = tuple(CASES),
    repeats: int = 3,
    seed: int = 0,
) -> list[StudyRow]:
    """Force error and cost of the Z-map for a range of cell sizes.

    Parameters
    ----------
    cells : tuple of float
        Cell edges to test, m.
    cases : tuple of str
        Keys of :data:`CASES`.
    repeats : int
        Random grid alignments per case.
    seed : int
        Seed of the alignments.

    Returns
    -------
    list of StudyRow
        One row per (cell, case).
    """
    rows = []
    for cell in cells:
        forces, t_step, members = run_cases(cell, list(cases), repeats, seed)
        n_ref = math.ceil(REFERENCE_FOOTPRINT[0] / cell - 1e-9) * math.ceil(REFERENCE_FOOTPRINT[1] / cell - 1e-9)
        for case in cases:
            ref = reference_force(case)
            err = np.hypot(*(forces[case] - ref[None, :]).T) / np.hypot(*ref)
            rows.append(StudyRow(cell, case, float(err.max()), float(err.mean()), t_step, members, 4 * n_ref))
    return rows


def format_rows(rows: list[StudyRow]) -> str:
    """Markdown table of study rows."""
    lines = ["| cell (mm) | case | max error (%) | mean error (%) | CPU time/step (ms, batch) | Z-map 100x100 mm (MB) |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(
            f"| {r.cell * 1e3:.3g} | {r.case} | {100 * r.max_error:.2f} | {100 * r.mean_error:.2f} | "
            f"{1e3 * r.time_per_step:.2f} (B={r.members}) | {r.memory_reference / 1e6:.1f} |"
        )
    return "\n".join(lines)
