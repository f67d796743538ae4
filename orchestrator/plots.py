"""Overview figure of a run: position, speed, following error, cutting load vs time."""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from .atomic import atomic_write_bytes
from .recording import Recording


#: Points per drawn channel: samples are reduced to their min and max in this many bins (a 1 kHz recording of a
#: 10 min program has 600 000 samples for a panel about 1 000 pixels wide).
PLOT_BINS = 2000
#: Above this many source-line changes the dotted line markers are left out (they would grey the panels).
MAX_LINE_MARKERS = 500


def _line_boundaries(recording: Recording) -> np.ndarray:
    lines = recording["line"]
    change = np.flatnonzero(np.diff(lines) != 0) + 1
    return recording.t[change]


def envelope(t: np.ndarray, y: np.ndarray, bins: int = PLOT_BINS) -> tuple[np.ndarray, np.ndarray]:
    """The samples a plot of ``y`` over ``t`` needs: each bin's smallest and largest value, in time order.

    Parameters
    ----------
    t, y : ndarray (n,)
        Sample times and values.
    bins : int
        Bins of equal sample count; the last ``n mod bins`` samples are kept as they are.

    Returns
    -------
    t, y : ndarray (m,)
        ``m <= 2 * bins + n // bins`` samples: the drawn line reaches every bin's extremes, so peaks stay
        visible. A bin holding NaN keeps a NaN sample (a gap). All samples when ``n <= 2 * bins``.
    """
    n = len(y)
    if n <= 2 * bins:
        return t, y
    width = n // bins
    body = np.asarray(y[: bins * width]).reshape(bins, width)
    start = np.arange(bins) * width
    pair = np.sort(np.stack((start + body.argmin(axis=1), start + body.argmax(axis=1)), axis=1), axis=1)
    keep = np.concatenate((pair.ravel(), np.arange(bins * width, n)))
    return t[keep], y[keep]


def overview_png(recording: Recording, path: Path, title: str = "") -> Path:
    """Draw the overview of a single-member recording and write it atomically as PNG.

    Panels: axis reference and actual position (mm), path feed (mm/min) and
    spindle speed (rpm), following error per axis (µm), cutting load (N)
    when present. Dotted vertical lines mark source-line changes (up to
    ``MAX_LINE_MARKERS`` of them). Long recordings are drawn through
    :func:`envelope` (every bin's extremes).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    has_fe = all(f"{a}_mm" in recording for a in "xyz")
    has_load = "fc_N" in recording
    panels = 2 + int(has_fe) + int(has_load)
    fig, axes = plt.subplots(panels, 1, figsize=(10, 2.4 * panels), sharex=True)
    t = recording.t

    def plot(ax, y: np.ndarray, **style) -> None:
        ax.plot(*envelope(t, y), **style)

    ax = axes[0]
    for a, color in zip("xyz", ("C0", "C1", "C2")):
        if f"{a}_ref_mm" in recording:
            plot(ax, recording[f"{a}_ref_mm"], color=color, lw=1, label=f"{a} ref")
        if f"{a}_mm" in recording:
            plot(ax, recording[f"{a}_mm"], color=color, lw=1, ls="--", label=f"{a} actual")
    ax.set_ylabel("position [mm]")
    ax.legend(ncol=6, fontsize=7, loc="upper right")
    ax = axes[1]
    if "feed_mm_per_min" in recording:
        plot(ax, recording["feed_mm_per_min"], color="k", lw=1, label="path feed [mm/min]")
    ax.set_ylabel("feed [mm/min]")
    if "spindle_rpm" in recording:
        ax2 = ax.twinx()
        plot(ax2, recording["spindle_rpm"], color="C3", lw=1, label="spindle [rpm]")
        if "spindle_ref_rpm" in recording:
            plot(ax2, recording["spindle_ref_rpm"], color="C3", lw=0.8, ls=":")
        ax2.set_ylabel("spindle [rpm]", color="C3")
    row = 2
    if has_fe:
        ax = axes[row]
        for a, color in zip("xyz", ("C0", "C1", "C2")):
            plot(ax, recording.following_error_um(a), color=color, lw=1, label=a)
        ax.set_ylabel("following error [µm]")
        ax.legend(ncol=3, fontsize=7, loc="upper right")
        row += 1
    if has_load:
        ax = axes[row]
        if "fc_peak_N" in recording:
            plot(ax, recording["fc_peak_N"], color="C4", lw=0.6, alpha=0.6, label="peak per step")
        plot(ax, recording["fc_N"], color="C4", lw=1, label="Fc")
        ax.set_ylabel("cutting load [N]")
        ax.legend(fontsize=7, loc="upper right")
    boundaries = _line_boundaries(recording)
    if len(boundaries) <= MAX_LINE_MARKERS:
        for ax in axes:
            ax.vlines(boundaries, 0.0, 1.0, transform=ax.get_xaxis_transform(), colors="0.8", lw=0.5, ls=":",
                      zorder=0)
    axes[-1].set_xlabel("time [s]")
    if title:
        axes[0].set_title(title)
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    plt.close(fig)
    return atomic_write_bytes(Path(path), buffer.getvalue())
