"""Small cases for the optimiser tests (a few seconds of cycle each; helpers only, no tests here)."""
from __future__ import annotations

from pathlib import Path

CASE_TOML = """program = "program.nc"
[stock]
min = [0.0, 0.0, -2.0]
max = [4.0, 6.0, 0.0]
[tool]
diameter_mm = 6.0
flutes = 2
"""

#: Two adjacent cutting lines (7 and 8) of a 1 mm deep full slot; line 8 is `second_mm` long.
PROGRAM = """%
O0002 (TWO-LINE SLOT)
G21 G17 G90 G94 G54
S3000 M3
G0 X-3.5 Y3. Z1.
G1 Z-1. F600
X0.5 F300 (SLOT PART 1)
X{x_end} (SLOT PART 2)
G0 Z1.
M30
%
"""


def write_case(folder: Path, second_mm: float = 2.0) -> Path:
    """Write ``case.toml`` and ``program.nc`` into ``folder``; returns the folder."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "case.toml").write_text(CASE_TOML)
    (folder / "program.nc").write_text(PROGRAM.format(x_end=f"{0.5 + second_mm:.1f}"))
    return folder
