"""Forced harmonics folded by a logger's sampling are not chatter (`orchestrator.diagnose.cutting_locate`).

Without an anti-alias filter a force sample spacing T folds a component at f to |f - k / T| in [0, 1 / (2 T)].
At 6000 rpm a 2-flute tool's tooth-passing harmonics (200, 400, 600 ... Hz) land on the 100 Hz spindle grid
only when T is a whole number of tenths of a revolution (1 ms); at 1.7 ms the 400 Hz harmonic lands at
588.24 - 400 = 188.24 Hz, off the grid, and the chatter search once named it chatter (2.3 ms: 600 Hz at
165.2 Hz). Recordings: the independent truth of the short program with a 2-flute tool (the twin's own
physics: it agrees with the twin's cutting component to 1e-6 N, `test_diagnose_cutting_truth.py`), 1 N noise.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from orchestrator.diagnose import diagnose
from orchestrator.diagnose.cutting_case import CASE_TOML, SHORT_PROGRAM, write_cutting_case
from orchestrator.diagnose.cutting_locate import alias_frequency, forced_orders
from orchestrator.diagnose.truth_cutting import Dynamometer

TWO_FLUTES = CASE_TOML.replace("flutes = 3", "flutes = 2")
F_SPINDLE = 100.0                     # 6000 rpm
MODE = {"frequency_Hz": 1150.0, "damping_ratio": 0.03, "stiffness_N_per_um": 30.0}


@pytest.mark.parametrize("spacing", [1e-3, 1.7e-3, 2.3e-3, 0.4e-3])
def test_alias_is_the_harmonic_folded_at_the_nyquist_frequency(spacing):
    f = np.arange(1, 201) * F_SPINDLE                       # spindle harmonics up to 20 kHz
    k = np.arange(0, 100)[:, None]
    brute = np.abs(f[None, :] - k / spacing)                # |m f_sp - k / T| for every k ...
    brute = np.where(brute <= 0.5 / spacing + 1e-9, brute, np.inf).min(axis=0)  # ... the one within Nyquist
    np.testing.assert_allclose(alias_frequency(f, spacing), brute, atol=1e-9)
    assert np.all(alias_frequency(f, spacing) <= 0.5 / spacing + 1e-9)


def test_the_tooth_harmonics_of_the_recordings():
    assert alias_frequency(400.0, 1.7e-3) == pytest.approx(1 / 1.7e-3 - 400.0)     # 188.24 Hz
    assert alias_frequency(600.0, 2.3e-3) == pytest.approx(600.0 - 1 / 2.3e-3)     # 165.22 Hz
    assert alias_frequency(1000.0, 1.7e-3) == pytest.approx(2 / 1.7e-3 - 1000.0)   # 176.47 Hz: 5th tooth harmonic
    assert alias_frequency(400.0, 1e-3) == 400.0 and alias_frequency(700.0, 1e-3) == pytest.approx(300.0)
    # the orders that fold onto 188.24 Hz at 1.7 ms (100 spindle revolutions are 17 samples: m and 100 - m
    # alias alike), the 4th (2nd tooth harmonic) first
    orders = forced_orders(1 / 1.7e-3 - 400.0, F_SPINDLE, 1.7e-3, tol_hz=0.5)
    assert orders.tolist() == [4, 96, 104, 196]
    # a chatter at 1348 Hz folds to 171.5 Hz: 5 Hz from the 5th tooth harmonic's alias, no order within 0.5 Hz
    assert alias_frequency(1348.0, 1.7e-3) == pytest.approx(1348.0 - 2 / 1.7e-3)
    assert forced_orders(alias_frequency(1348.0, 1.7e-3), F_SPINDLE, 1.7e-3, tol_hz=0.5).size == 0


def _case(tmp_path, name, effects, period_s):
    return write_cutting_case(tmp_path / name, effects, 11, program=SHORT_PROGRAM,
                              dynamometer=Dynamometer(period_s=period_s), case_toml=TWO_FLUTES)


def test_clean_recording_at_1_7_ms_names_nothing(tmp_path):
    d = diagnose(_case(tmp_path, "clean", {}, 1.7e-3), drives=False)
    assert d.effects == [] and d.unexplained == [], d.log      # was chatter at 188.09 Hz
    notes = [n for n in d.cutting.notes if "folded by the 1.7 ms sampling" in n]
    assert any("188.2 Hz is the tooth-passing harmonic 2 (400 Hz)" in n and "not chatter" in n for n in notes)


@pytest.mark.parametrize("period_s, alias_hz", [(1e-3, 348.0), (1.7e-3, 171.5)])
def test_real_chatter_is_named_at_its_alias(tmp_path, period_s, alias_hz):
    # the mode at 1150 Hz makes the 2-flute 2 mm slot chatter at about 1348 Hz (README scorecard); without an
    # anti-alias filter a 1 ms logger sees it at 348 Hz, a 1.7 ms logger at 1348 - 2 x 588.24 = 171.5 Hz, beside
    # the forced 176.5 Hz (5th tooth harmonic) and 188.2 Hz (2nd) of the 3 mm side pass, which are set aside
    folder = _case(tmp_path, "chatter", {"chatter": MODE}, period_s)
    d = diagnose(folder, drives=False)
    assert [e["effect"] for e in d.effects] == ["chatter"], d.log
    f = d.effects[0]["parameters"]["frequency_Hz"]
    assert f == pytest.approx(alias_hz, abs=1.5)               # at 1.7 ms was the median 179.9 of 171.5 and 188.2
    assert len(d.effects[0]["where"]["time_s"]) == 1            # only the deep slot
    assert f"folded by the {period_s * 1e3:.3g} ms sampling" in d.effects[0]["evidence"]
    assert json.loads((folder / "truth.json").read_text())["cutting_effects"]["chatter"] == MODE
