"""The overview figure of long recordings: the envelope keeps every bin's extremes; line markers are capped."""
from __future__ import annotations

import numpy as np

from orchestrator.plots import MAX_LINE_MARKERS, envelope, overview_png
from orchestrator.recording import Recording


def test_envelope_keeps_each_bins_extremes_in_time_order():
    rng = np.random.default_rng(3)
    t = np.arange(100_003) * 1e-3
    y = np.sin(2 * np.pi * 7.0 * t) + 0.1 * rng.normal(size=t.size)
    y[5_000] = 40.0  # a one-sample spike
    te, ye = envelope(t, y, bins=500)
    width = t.size // 500
    assert len(te) == 2 * 500 + t.size % 500
    assert np.all(np.diff(te) >= 0)
    body = y[: 500 * width].reshape(500, width)
    assert np.array_equal(np.sort(ye[: 1000].reshape(500, 2), axis=1),
                          np.stack((body.min(axis=1), body.max(axis=1)), axis=1))
    assert ye.max() == 40.0 and ye.min() == y.min()
    short_t, short_y = envelope(t[:800], y[:800], bins=500)
    assert np.array_equal(short_t, t[:800]) and np.array_equal(short_y, y[:800])


def test_line_markers_are_one_collection_per_panel_and_left_out_above_the_cap(tmp_path, monkeypatch):
    import matplotlib.axes

    drawn = []
    vlines = matplotlib.axes.Axes.vlines
    monkeypatch.setattr(matplotlib.axes.Axes, "vlines", lambda self, x, *a, **k: drawn.append(len(x)) or
                        vlines(self, x, *a, **k))
    for changes, expected in ((10, [10, 10]), (4 * MAX_LINE_MARKERS, [])):
        drawn.clear()
        t = np.arange(4 * MAX_LINE_MARKERS + 1) * 1e-3
        line = np.minimum(np.arange(t.size), changes).astype(float)  # ``changes`` changes of line
        rec = Recording.from_channels({"t_s": t, "line": line, "x_ref_mm": t, "spindle_rpm": np.full(t.size, 6e3)})
        path = overview_png(rec, tmp_path / "o.png")
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert drawn == expected  # two panels: position, feed and spindle
