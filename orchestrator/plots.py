"""Overview figure of a run: position, speed, following error, cutting load vs time."""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from .atomic import atomic_write_bytes
from .recording import Recording


def _line_boundaries(recording: Recording) -> np.ndarray:
    lines = recording["line"]
    change = np.flatnonzero(np.diff(lines) != 0) + 1
    return recording.t[change]


def overview_png(recording: Recording, path: Path, title: str = "") -> Path:
    """Draw the overview of a single-member recording and write it atomically as PNG.

    Panels: axis reference and actual position (mm), path feed (mm/min) and
    spindle speed (rpm), following error per axis (µm), cutting load (N)
    when present. Dotted vertical lines mark source-line changes.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    has_fe = all(f"{a}_mm" in recording for a in "xyz")
    has_load = "fc_N" in recording
    panels = 2 + int(has_fe) + int(has_load)
    fig, axes = plt.subplots(panels, 1, figsize=(10, 2.4 * panels), sharex=True)
    t = recording.t
    ax = axes[0]
    for a, color in zip("xyz", ("C0", "C1", "C2")):
        if f"{a}_ref_mm" in recording:
            ax.plot(t, recording[f"{a}_ref_mm"], color=color, lw=1, label=f"{a} ref")
        if f"{a}_mm" in recording:
            ax.plot(t, recording[f"{a}_mm"], color=color, lw=1, ls="--", label=f"{a} actual")
    ax.set_ylabel("position [mm]")
    ax.legend(ncol=6, fontsize=7, loc="upper right")
    ax = axes[1]
    if "feed_mm_per_min" in recording:
        ax.plot(t, recording["feed_mm_per_min"], color="k", lw=1, label="path feed [mm/min]")
    ax.set_ylabel("feed [mm/min]")
    if "spindle_rpm" in recording:
        ax2 = ax.twinx()
        ax2.plot(t, recording["spindle_rpm"], color="C3", lw=1, label="spindle [rpm]")
        if "spindle_ref_rpm" in recording:
            ax2.plot(t, recording["spindle_ref_rpm"], color="C3", lw=0.8, ls=":")
        ax2.set_ylabel("spindle [rpm]", color="C3")
    row = 2
    if has_fe:
        ax = axes[row]
        for a, color in zip("xyz", ("C0", "C1", "C2")):
            ax.plot(t, recording.following_error_um(a), color=color, lw=1, label=a)
        ax.set_ylabel("following error [µm]")
        ax.legend(ncol=3, fontsize=7, loc="upper right")
        row += 1
    if has_load:
        ax = axes[row]
        if "fc_peak_N" in recording:
            ax.plot(t, recording["fc_peak_N"], color="C4", lw=0.6, alpha=0.6, label="peak per step")
        ax.plot(t, recording["fc_N"], color="C4", lw=1, label="Fc")
        ax.set_ylabel("cutting load [N]")
        ax.legend(fontsize=7, loc="upper right")
    for boundary in _line_boundaries(recording):
        for ax in axes:
            ax.axvline(boundary, color="0.8", lw=0.5, ls=":", zorder=0)
    axes[-1].set_xlabel("time [s]")
    if title:
        axes[0].set_title(title)
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    plt.close(fig)
    return atomic_write_bytes(Path(path), buffer.getvalue())
