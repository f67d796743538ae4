"""FANUC Custom Macro B (0i-MF/31i-B) in the NC kernel: variables, expressions, IF/WHILE/GOTO, G65 calls.

Modules, each with its conventions: :mod:`.statements` (telling macro lines from plain blocks, parsing),
:mod:`.expressions` (operators, functions, vacant values), :mod:`.variables` (#0, locals per G65 level, common
variables), :mod:`.system` (system variables), :mod:`.words` (NC words with variable values), :mod:`.loops`
(GOTO search, DO/END pairs), :mod:`.calls` (G65 arguments), :mod:`.runtime` (running them in the interpreter).
Plain lines never reach this package: they are lexed by :mod:`..lexer` exactly as before.
"""
from __future__ import annotations

from .statements import MacroLine, is_macro_line, parse_line, scan_line

__all__ = ["MacroLine", "is_macro_line", "parse_line", "scan_line"]
