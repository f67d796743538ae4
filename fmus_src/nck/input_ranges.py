"""Input ranges of the program's numbers (FANUC IS-B, 8 digits).

Conventions
-----------
* Input ranges (FANUC IS-B, 8 digits): X Y Z I J K R within +-99999.999 mm
  (G21) or +-9999.9999 in (G20); dwell at most 99999.999 s; T at most
  99999999; a number has at most 32 characters (ASCII digits only; the lexer,
  :data:`.lexer.MAX_NUMBER_CHARS`). Beyond them: :class:`GCodeError` (a 1e400
  would otherwise become ``inf``).
"""
from __future__ import annotations

from .codes import ValueWords
from .errors import ErrorFactory

#: Input range of X Y Z I J K R words (FANUC IS-B, 8 digits): mm under G21, inch under G20.
MAX_COORDINATE = {"mm": 99999.999, "in": 9999.9999}
#: Longest dwell, s (FANUC: 8 digits of P in ms).
MAX_DWELL = 99999.999
#: Largest tool number (FANUC: 8 digits).
MAX_TOOL = 99999999


def check_coordinates(vals: ValueWords, unit_name: str, err: ErrorFactory, letters: str = "XYZIJKRQ") -> None:
    """Length words within :data:`MAX_COORDINATE` of the unit in effect (``"mm"`` or ``"in"``).

    Parameters
    ----------
    vals : ValueWords
        The block's value words.
    unit_name : str
        ``"mm"`` (G21) or ``"in"`` (G20).
    err : ErrorFactory
        Builds the error of the block.
    letters : str
        The words that are lengths in this block: X Y Z I J K R Q, without K in a canned-cycle block (there
        K is the repeat count, whose range the cycle checks).
    """
    limit = MAX_COORDINATE[unit_name]
    for a in letters:
        if a in vals and abs(vals[a].value) > limit:
            raise err(a + vals[a].text, f"{a}{vals[a].text} is beyond the input range of {limit} {unit_name}",
                      f"|{a}| <= {limit} {unit_name}")
