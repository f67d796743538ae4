"""The bound of the twin's thrust from its run without cutting (orchestrator.diagnose.thrust_gate).

A plunge of a 6 mm 2-flute end mill into solid A6061 at F300 S6000 (ka 0.28, Kt 1230 N/mm2) has the thrust
``ka Kt 2 pi R vz / omega`` = 2 x 0.28 x 1230 x 0.025 x 3 = 51.66 N (as ``test_diagnose_thrust_load``): the
bound must reach it. The cutting tests' short program plunges beside the block and cuts at fixed heights:
no thrust at all, and the twin's run with cutting confirms it (no Z load).
"""
from __future__ import annotations

import pytest

from orchestrator.case import load_case
from orchestrator.diagnose.cutting_case import CASE_TOML, SHORT_PROGRAM
from orchestrator.diagnose.prepare import NEGLIGIBLE_LOAD_N, twin_commands, twin_loads
from orchestrator.diagnose.thrust_gate import thrust_bound

THRUST = 2 * 0.28 * 1230.0 * 0.025 * 3.0   # N

PLUNGE = """%
O0001 (PLUNGE INTO THE BLOCK)
N10 G21 G17 G90 G94
N20 S6000 M3
N30 G0 X8. Y10. Z1.
N40 G1 Z-2. F300
N50 G0 Z5.
N60 M30
%
"""


def _case(tmp_path, program, flutes):
    (tmp_path / "program.nc").write_text(program)
    (tmp_path / "case.toml").write_text(CASE_TOML.replace("flutes = 3", f"flutes = {flutes}"))
    return load_case(tmp_path)


def test_a_plunge_into_the_block_is_bounded_by_the_full_disc_thrust(tmp_path):
    case = _case(tmp_path, PLUNGE, 2)
    bound = thrust_bound(case, case.machine, twin_commands(case, case.machine))
    assert bound >= 0.99 * THRUST          # the feed's own thrust (the twin may overshoot the feed a little)
    assert bound < 1.5 * THRUST


def test_slots_at_fixed_heights_have_no_thrust_and_the_twin_agrees(tmp_path):
    case = _case(tmp_path, SHORT_PROGRAM, 3)
    assert thrust_bound(case, case.machine, twin_commands(case, case.machine)) < 0.1 * NEGLIGIBLE_LOAD_N
    loads = twin_loads(case, case.machine)   # the run with cutting the bound lets the diagnosis skip
    assert loads is not None and "z" not in loads.mean and {"x", "y"} <= set(loads.mean)
