"""Cutting-coefficient identification from forces of a partial-immersion cut simulated on the twin.

Known, non-default coefficients (Kt = 0.95e9 N/m2, Ke = 0.38) are identified
back from fx, fy (linear least squares) and from fc alone, with logger
imperfections; the spindle phase at the start of the log is unknown to the
identifier.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from orchestrator.atomic import atomic_write_text
from orchestrator.identify import IdentificationError, Imperfections, identify_cutting
from orchestrator.identify.synthetic import degrade, synthetic_case
from orchestrator.machine import load_machine
from orchestrator.recording import Recording

KT, KE = 0.95e9, 0.38

PROGRAM = """%
O0001
G21 G90 G94 G17
S6000 M3
G0 X-4. Y4.
G0 Z-1.
G1 X3. F450
G0 Z2.
M30
%
"""
CASE = """program = "program.nc"
recording = "recording.csv"
[stock]
min = [0.0, 0.0, -5.0]
max = [8.0, 5.5, 0.0]
[tool]
diameter_mm = 6.0
flutes = 2
[machine]
parameters = "default"
"""


@pytest.fixture(scope="module")
def cut_case(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cutting") / "case"
    atomic_write_text(folder / "program.nc", PROGRAM)
    atomic_write_text(folder / "case.toml", CASE)
    truth = load_machine("default").with_values("material.A6061", kt_N_per_m2=KT, ke=KE)
    clean, _ = synthetic_case(folder, truth, Imperfections(0, 0, 0, 0, 0, 0))
    # the logger starts 0.3 s before the cut and the spindle phase there is unknown
    keep = clean.t >= 1.0
    channels = {n: np.asarray(clean[n])[keep] for n in clean.channels}
    trimmed = Recording.from_channels(channels, clean.units)
    return folder, trimmed


def test_kt_ke_from_fx_fy_within_tolerance(cut_case, tmp_path):
    folder, clean = cut_case
    degrade(clean, Imperfections(), seed=31).write_csv(folder / "recording.csv")
    fit = identify_cutting([folder])
    assert fit.kt_ == pytest.approx(KT, rel=0.03)
    assert fit.ke_ == pytest.approx(KE, rel=0.10)
    assert fit.rms_["fx"] < 1.5  # the 1 N dynamometer noise
    files = fit.write(tmp_path / "out")
    fitted = load_machine(files["machine"])
    assert fitted.table("material.A6061")["kt_N_per_m2"] == pytest.approx(fit.kt_)
    assert "identified: cutting default" in fitted.provenance["material.A6061.ke"]
    assert json.loads(files["report"].read_text())["ke"] == pytest.approx(fit.ke_)
    assert files["cutting_load"].stat().st_size > 1000


def test_ten_times_the_noise_degrades_gracefully(cut_case):
    folder, clean = cut_case
    degrade(clean, Imperfections().scaled(10.0), seed=32).write_csv(folder / "recording.csv")
    fit = identify_cutting([folder], phases=8)
    assert fit.kt_ == pytest.approx(KT, rel=0.05)
    assert fit.ke_ == pytest.approx(KE, rel=0.15)


def test_fc_only_fixes_kt_sqrt_one_plus_ke_squared(cut_case):
    """With one tooth in the cut Fc = Kt d h sqrt(1 + Ke^2): only that product is identifiable from fc."""
    folder, clean = cut_case
    rec = degrade(clean, Imperfections(), seed=33)
    channels = {n: np.asarray(rec[n]) for n in rec.channels if n not in ("fx_N", "fy_N")}
    Recording.from_channels(channels, rec.units).write_csv(folder / "recording.csv")
    fit = identify_cutting([folder], phases=8)
    assert fit.notes_ and "not separately identifiable" in fit.notes_[0]
    assert fit.kt_ * math.hypot(1.0, fit.ke_) == pytest.approx(KT * math.hypot(1.0, KE), rel=0.03)


def test_stock_not_cut_is_an_error(cut_case, tmp_path):
    folder, clean = cut_case
    other = tmp_path / "case"
    atomic_write_text(other / "program.nc", PROGRAM)
    atomic_write_text(other / "case.toml", CASE.replace("min = [0.0, 0.0, -5.0]", "min = [50.0, 50.0, -5.0]")
                      .replace("max = [8.0, 5.5, 0.0]", "max = [60.0, 60.0, 0.0]"))
    degrade(clean, Imperfections(), seed=34).write_csv(other / "recording.csv")
    with pytest.raises(IdentificationError, match="cuts the stock"):
        identify_cutting([other])
