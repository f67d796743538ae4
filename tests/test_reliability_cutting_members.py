"""A member that fails upstream of the cutting load fails alone, in Z-map and path mode.

When a batch member's servo runs away, its drive outputs turn NaN (the
member is failed with a reason by the MCU alarm or the master's divergence
check). The cutting load then sees non-finite tool positions for that member
only: it must hold that member still and blank its outputs, and every other
member must produce exactly the recording of its solo run.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from orchestrator.case import load_case
from orchestrator.master import Master, MasterSettings
from orchestrator.twin import TwinOptions, build_twin

ROOT = Path(__file__).resolve().parents[1]
CASE = load_case(ROOT / "models" / "examples" / "paper_part")
# a 1 mm deep full slot, 4 mm long, into the paper part's stock (30 x 20 x 10 mm, top at Z0)
PROGRAM = "G21 G90 G94\nS6000 M3\nG0 X-4. Y6. Z1.\nG1 Z-1. F200\nX4. F300\nG0 Z1.\nM30\n"


def run(batch: int, mode: str, compiled: bool, runaway: int | None = None):
    options = TwinOptions(cutting_mode=mode, start_mm=(-4.0, 6.0, 1.0))
    twin = build_twin(CASE, batch=batch, program_text=PROGRAM, options=options)
    if runaway is not None:  # positive velocity feedback on X: the member runs away as soon as X moves
        gain = twin.mcu.get("x_velocity_p_scale")
        gain[runaway] = -1.0
        twin.mcu.set("x_velocity_p_scale", gain)
    settings = MasterSettings(step=twin.options.step, time_limit=8.0, stop_when=twin.stop_when,
                              limits=twin.limits or {}, check_every=10, compiled=compiled)
    with np.errstate(over="ignore", invalid="ignore"):
        return Master(twin.system, settings, twin.probes).run()


@pytest.mark.parametrize("mode,compiled", [("path", True), ("path", False), ("zmap", False)])
def test_a_runaway_member_fails_alone_and_the_cutting_member_equals_its_solo_run(mode, compiled):
    solo = run(1, mode, compiled)
    assert solo.success and np.nanmax(solo.recording["fc_N"]) > 10.0  # it really cuts
    both = run(2, mode, compiled, runaway=1)
    assert both.success and both.failed.tolist() == [False, True]
    assert both.failures[1] is not None and "x" in both.failures[1]
    n = len(solo.recording)
    for name in solo.recording.channels:
        col = both.recording[name] if name == "t_s" else both.recording[name][:, 0]
        np.testing.assert_array_equal(col[:n], solo.recording[name], err_msg=f"{mode}: channel {name}")
    # the failed member's cutting outputs are blanked, never a plausible-looking force
    after = np.flatnonzero(np.isnan(both.recording["x_mm"][:, 1]))
    assert after.size and np.isnan(both.recording["fc_N"][after[-1], 1])
