"""Subprogram calls at run time: the M98/M99 words of a block, the stack of active calls and M99 returns.

Finding the subprograms of a file and reading the M98/M99 words: :mod:`.subprograms`.

Conventions
-----------
* Subprograms (FANUC 0i-MF/31i-B): ``M98 P1001``, ``M98 P1001 L2`` and
  ``M98 P21001`` (twice) call O1001; other words of the M98 block (a move)
  run first, then the call. M99 returns to the block after the M98 (or runs
  the subprogram again while repeats remain); ``M99 P<seq>`` returns to the
  caller's block N<seq> instead. The modal state is one: a
  subprogram that switches to G91 must switch back itself, and its F, S,
  offsets and canned cycle carry over to the caller. Calls nest at most 10
  levels (31i-B); deeper (e.g. a subprogram calling itself), a missing
  program, M99 in the main program (FANUC: an endless restart), M99 P<seq>
  without that N in the caller or making the program endless, and M98 with
  G4/G28/G30/G53 or a canned-cycle code are errors.
* Haas ``M97 P<n> [L<k>]`` calls the local subprogram from the block N<n> of the running program to its
  M99 (:func:`.subprograms.local_subprogram`); it is a frame on the same stack as M98 (same nesting limit,
  same returns, same restrictions on the block). Blocks from a subprogram carry the
  subprogram's own source lines; :attr:`Program.segments` gives the order in
  which lines ran.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence

from .codes import GWords, MWords, ValueWords
from .errors import ErrorFactory, GCodeError
from .subprograms import (
    MAX_NESTING, Call, Return, Subprogram, find_sequence, local_subprogram, main_program_end, read_call,
    read_local_call, read_return,
)

if TYPE_CHECKING:
    from .macro.calls import MacroCall


def subprogram_words(gs: GWords, ms: MWords, vals: ValueWords, err: ErrorFactory) -> tuple[Call | None, Return]:
    """The M98 call and the M99 return of a block (pops the P and L words they use).

    Returns
    -------
    call : Call or None
        The M98 (or M97, ``local``) call of the block, None without one.
    ret : Return
        The M99 return of the block (plain :class:`Return` when the block has no M99 or its P belongs to
        G4/G10/G30).
    """
    call: Call | None = None
    ret = Return()
    if "subprogram" in ms:
        code = ms["subprogram"][0]
        if "end" in ms:
            raise err(f"M{ms['end'][0]}", f"M{code} and M{ms['end'][0]} in one block",
                      f"M{code} and the program end M30/M2 in separate blocks")
        if code in (97, 98):
            drill = "canned cycle" in gs and gs["canned cycle"][0] != 80
            if "non-modal" in gs or drill:
                other = (gs.get("non-modal") or gs["canned cycle"])[1]
                raise err("G" + other.text, f"G{other.text} and M{code} in one block",
                          f"M{code} P<n> alone or with a G0-G3 move (the move runs first, then the call)")
            read = read_call if code == 98 else read_local_call
            call = read(vals.pop("P", None), vals.pop("L", None), err)
        elif gs.get("non-modal", (None,))[0] not in (4, 10, 30):  # there P is the dwell, offset or reference no.
            ret = read_return(vals.pop("P", None), err)
    return call, ret


@dataclass
class Frame:
    """An active subprogram call: what runs, where it was called from, and how many runs remain."""

    sub: Subprogram
    call_line: int  # 1-based line of the M98 block
    return_pc: int  # 0-based index of the line after the M98 block
    remaining: int
    macro: MacroCall | None = None  # a G65 macro call (its own local variables, see .macro), None for M98
    #: (lines run in subprograms, macro lines run) when the current pass started: a pass that ran no macro line
    #: is run exactly alike by every later pass, so the lines still to come are known (the runaway guard)
    pass_start: tuple[int, int] = (0, 0)


def return_target(sequence: int, lines: Sequence[str], stack: list[Frame], subs: dict[int, Subprogram] | None,
                  frame: Frame, line: int, text: str, file: str, block_delete: bool, jumps: set[tuple]) -> int:
    """0-based line index M99 P<sequence> returns to: the block N<sequence> of the caller (after ``stack.pop()``).

    Raises a :class:`GCodeError` when the caller has no such block, or when the same return with the same calls
    active happened before (the program has no conditions: it would repeat endlessly).
    """
    word = f"P{sequence}"
    if stack:
        caller = stack[-1].sub
        first, last, name = caller.first, caller.end, f"subprogram {caller.name}"
    else:
        subs_start = min((s.start for s in (subs or {}).values()), default=len(lines))
        end = main_program_end(lines, frame.call_line - 1, file, block_delete)
        first, last, name = 0, min(subs_start - 1, len(lines) - 1 if end is None else end), "the main program"
    target = find_sequence(lines, first, last, sequence)
    if target is None:
        raise GCodeError(file, line, word, f"a block N{sequence} in {name} (lines {first + 1}-{last + 1}), "
                         "which called this subprogram", f"{name} has no block N{sequence} to return to", text)
    state = (target, tuple((f.sub.number, f.return_pc, f.remaining) for f in stack))
    if state in jumps:
        raise GCodeError(file, line, word, "a return that does not lead back to the same M98 call (an M30 or M2 "
                         "after N{0}, or M99 without P)".format(sequence),
                         f"returning to N{sequence} (line {target + 1}) repeats the program endlessly: the same "
                         f"calls run again from there (FANUC would loop forever)", text)
    jumps.add(state)
    return target


def called_subprogram(call: Call, subs: dict[int, Subprogram], stack: list[Frame], line: int, text: str,
                      file: str, code: str = "M98", lines: Sequence[str] = (), block_delete: bool = False,
                      ) -> Subprogram:
    """The subprogram an M98 (or G65, ``code``; or M97, ``call.local``) block calls, or a :class:`GCodeError`
    (missing program or block N, nesting too deep; M97, M98 and G65 calls count together).

    ``lines`` and ``block_delete`` (the program's source lines and the block delete switch) are needed for an
    M97 call: its block N<n> is searched in the running program (:func:`.subprograms.local_subprogram`).
    """
    if call.local:
        code = "M97"
    word = f"{code} P{call.number}"
    if call.local:
        if stack:
            here = stack[-1].sub
            first, last, name = here.first, here.end, f"subprogram {here.name}"
        else:
            subs_start = min((s.start for s in subs.values()), default=len(lines))
            first, last, name = 0, subs_start - 1, "the main program"
        target = local_subprogram(call.number, first, last, lines, file, block_delete, name, line, text)
    elif call.number not in subs:
        have = ", ".join(f"O{n} (line {s.start + 1})" for n, s in sorted(subs.items())) or "none"
        raise GCodeError(file, line, word, f"one of the subprograms after the main program's M30: {have}",
                         f"subprogram O{call.number} is not in the file", text)
    else:
        target = subs[call.number]
    if len(stack) >= MAX_NESTING:
        active = " -> ".join(f.sub.name for f in stack)
        again = " (recursion: it is already running)" if any(f.sub == target for f in stack) else ""
        raise GCodeError(file, line, word, f"subprogram calls (M97, M98, G65) nested at most {MAX_NESTING} levels "
                         "deep (FANUC 31i-B)",
                         f"calling {target.name}{again} would nest {len(stack) + 1} levels ({active})", text)
    return target
