"""Fit plots (PNG, atomic writes): Stribeck curves (paper Fig. 3), servo replay (Fig. 5), cutting load (Fig. 6c)."""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from ..atomic import atomic_write_bytes


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> Path:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    _pyplot().close(fig)
    return atomic_write_bytes(Path(path), buffer.getvalue())


def stribeck_png(fit, axis: str, path: Path) -> Path:
    """Measured Stribeck points and fitted curve of one axis, both directions (signed, as Fig. 3)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for direction, sign, color in (("positive", 1.0, "C0"), ("negative", -1.0, "C3")):
        speed, force = fit.points(axis, direction)
        p = fit.params_[axis][direction]
        v = np.logspace(np.log10(max(speed.min() * 0.5, 1e-7)), np.log10(speed.max() * 1.1), 300)
        ax.plot(sign * speed * 6e4, sign * force, "o", color=color, ms=4, label=f"measured {direction}")
        ax.plot(sign * v * 6e4, sign * p.force(v), "-", color=color, lw=1.2,
                label=f"fit: Fc {p.coulomb:.0f} N, Fs {p.static:.0f} N, vs {p.stribeck_velocity * 6e4:.3g} mm/min, "
                      f"mu_v {p.viscous:.0f} N s/m")
    ax.set_xscale("symlog", linthresh=5.0)
    ticks = [-1e4, -1e3, -1e2, -1e1, 1e1, 1e2, 1e3, 1e4]
    ax.set_xticks(ticks, [f"{t:g}" for t in ticks])
    ax.set_xlabel("velocity [mm/min]")
    ax.set_ylabel("friction force [N]")
    ax.set_title(f"Stribeck curve, axis {axis.upper()} ({fit.method})")
    ax.grid(True, which="both", lw=0.3)
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    return _save(fig, path)


def servo_png(fit, axis: str, path: Path) -> Path:
    """Reference position, following error and current command measured vs simulated (Fig. 5)."""
    plt = _pyplot()
    traces = [tr for tr in fit.traces_ if axis in tr["e_meas"]]
    fig, axes = plt.subplots(3, len(traces), figsize=(9 * len(traces), 7.5), sharex="col", squeeze=False)
    for col, tr in enumerate(traces):
        t = tr["t"]
        axes[0, col].plot(t, tr["ref_mm"][axis], "k", lw=1)
        axes[0, col].set_ylabel("reference [mm]")
        axes[0, col].set_title(f"{tr['case']}: axis {axis.upper()}, Spp {fit.scales_[axis]['Spp']:.3f}, "
                               f"Svp {fit.scales_[axis]['Svp']:.3f}, Svi {fit.scales_[axis]['Svi']:.3f}")
        axes[1, col].plot(t, tr["e_meas"][axis], color="C0", lw=1, label="measured")
        axes[1, col].plot(t, tr["e_sim"][axis], color="C1", lw=1, ls="--", label="twin")
        axes[1, col].set_ylabel("following error [µm]")
        axes[1, col].legend(fontsize=7)
        axes[2, col].plot(t, tr["cur_meas"][axis], color="C0", lw=1, label="measured")
        axes[2, col].plot(t, tr["cur_sim"][axis], color="C1", lw=1, ls="--", label="twin")
        axes[2, col].set_ylabel("current command [A]")
        axes[2, col].set_xlabel("time [s]")
        for ax in axes[:, col]:
            ax.grid(True, lw=0.3)
    fig.tight_layout()
    return _save(fig, path)


def cutting_png(fit, path: Path) -> Path:
    """Cutting load measured vs simulated with the fitted Kt, Ke (Fig. 6c)."""
    plt = _pyplot()
    fig, axes = plt.subplots(len(fit.traces_), 1, figsize=(10, 3.2 * len(fit.traces_)), squeeze=False)
    for ax, tr in zip(axes[:, 0], fit.traces_):
        ax.plot(tr["t"], tr["fc_meas"], color="C0", lw=0.8, label="measured")
        ax.plot(tr["t"], tr["fc_sim"], color="C1", lw=0.8, ls="--", label="twin")
        ax.set_ylabel("cutting load [N]")
        ax.set_title(f"{tr['case']}: Kt {fit.kt_:.4g} N/m2, Ke {fit.ke_:.3f} ({fit.method})")
        ax.grid(True, lw=0.3)
        ax.legend(fontsize=7)
    axes[-1, 0].set_xlabel("time [s]")
    fig.tight_layout()
    return _save(fig, path)
