"""Blocks in canned-cycle mode (G73-G89 until G80 or a G0-G3): modal drilling data → the holes of :mod:`.cycles`.

Conventions
-----------
* FANUC semantics: the initial level is the Z position when the cycle mode starts; R (G91: from the initial
  level) and Z (G91: from the R point) stay modal as programmed and the levels are derived per hole
  (:func:`.cycles.cycle_levels`); Q, P are modal; K (repeat count, not modal) repeats the hole, moving by the
  X/Y increments each time under G91; a hole is drilled when the block holds X, Y, Z or R; K0 stores the
  data only.
* Under G95 the feed blocks of a hole keep their feed per revolution (spindle overrides rescale them).
* Tapping G84/G74 (feed = pitch x S, M29 rigid tapping): :mod:`.tapping`; G76/G87 need Q > 0 (the shift) and
  the spindle turning clockwise (M3); G87 needs Z above R and G98 (FANUC returns it to the initial level only).
* Under G16 the hole positions X/Y are polar (K repeats with a G91 angle make a bolt circle); under
  G51.1/G51/G68 the hole positions are transformed and the levels (initial, R, bottom) scaled with Z; Q, the
  G73/G83 return d and the G76/G87 shift (along the machine axes) are not (:mod:`.transforms`).
"""
from __future__ import annotations

import math
from dataclasses import replace

from .blocks import AXIS_INDEX, Block, Linear
from .codes import ValueWords
from .cycles import MAX_CYCLE_MOVES, TAPPING, CycleError, Hole, LevelWord, cycle_levels, expand_hole
from .dwell import dwell_seconds
from .errors import ErrorFactory, fmt_number
from .feed import block_feed
from .modal import ModalState
from .motion import SAME_POINT
from .polar import program_targets
from .settings import INCH
from .tapping import RIGID_ACTIVE, RIGID_PENDING, start_tapping, tap_feed
from .transforms import advance, check_cycle, z_work

#: Largest repeat count K of a canned cycle (FANUC: 4 digits).
MAX_REPEAT = 9999


def canned_cycle_block(st: ModalState, vals: ValueWords, code: int | None, line: int, err: ErrorFactory,
                       out: list[Block]) -> None:
    """A block in canned-cycle mode: store the drilling data and drill the hole(s) (see the module docstring).

    Parameters
    ----------
    st : ModalState
        Modal state with the cycle's modal data.
    vals : ValueWords
        The block's words (X Y Z R Q P K F).
    code : int or None
        The block's cycle code G73-G89, None when the block only continues the modal cycle.
    line : int
        1-based source line of the block.
    err : ErrorFactory
        Builds the error for this block.
    out : list of Block
        The program's blocks so far; the moves of the hole(s) are appended.
    """
    if code is not None:
        if st.rigid == RIGID_PENDING and code not in TAPPING:
            raise err(f"G{code}", f"canned cycle G{code} after M29 (FANUC alarm PS0203 style)",
                      "G84 or G74 after M29 S<rpm> (M29 selects rigid tapping)")
        if st.cycle is None:
            st.cycle_initial = st.prog[2]
        st.cycle = code
    gname = f"G{st.cycle}"
    if st.cycle in TAPPING and st.rigid == RIGID_PENDING:
        st.rigid = RIGID_ACTIVE
    if st.cycle in TAPPING and "Q" in vals:
        raise err("Q" + vals["Q"].text, f"Q in tapping cycle {gname} (peck tapping)",
                  f"{gname} X Y Z R P F K without Q (peck tapping is not supported)")
    for a in "IJ":
        if a in vals:
            raise err(a + vals[a].text, f"word {a} in canned cycle {gname}", "X Y Z R Q P K F words in a cycle block")
    scale = st.scale
    if "R" in vals:
        st.cycle_r = LevelWord(vals["R"].value * scale, not st.absolute)
    if "Z" in vals:
        st.cycle_bottom = LevelWord(vals["Z"].value * scale, not st.absolute)
    if "Q" in vals:
        q = vals["Q"]
        if q.value <= 0.0:
            raise err("Q" + q.text, f"peck depth Q{q.text} is not positive", "Q > 0 (depth of each peck)")
        st.cycle_q = q.value * scale
    if "P" in vals:
        st.cycle_dwell = dwell_seconds(vals["P"], err)
    repeat = 1
    if "K" in vals:
        k = vals["K"]
        if k.has_point or k.value < 0 or k.value > MAX_REPEAT:
            raise err("K" + k.text, f"repeat count K{k.text} is not an integer in 0..{MAX_REPEAT}",
                      "K0 (store the data only), K1 (default), ... K9999")
        repeat = int(k.value)
    if repeat == 0 or not any(a in vals for a in "XYZR"):
        return
    if st.cycle_r is None:
        raise err(gname, f"canned cycle {gname} without an R point", "an R word on this or an earlier cycle block")
    if st.cycle_bottom is None:
        raise err(gname, f"canned cycle {gname} without a hole bottom Z", "a Z word on this or an earlier cycle block")
    if st.xf.engaged:
        check_cycle(st, gname, err)
    u = 1.0 / scale
    unit_name = "in" if scale == INCH else "mm"
    r_level, bottom = cycle_levels(st.cycle_initial, st.cycle_r, st.cycle_bottom)
    if st.cycle == 87:  # back boring: from R below the part up to Z
        if bottom <= r_level + SAME_POINT:
            word = "Z" + vals["Z"].text if "Z" in vals else gname
            raise err(word, f"back boring G87 top Z {fmt_number(bottom * u)} {unit_name} is not above the R point "
                      f"{fmt_number(r_level * u)} {unit_name}", "Z above R (G87 bores upwards from R below the part)")
        if not st.return_initial:
            raise err(gname, "back boring G87 under G99", "G98: FANUC returns G87 to the initial level only "
                      "(the R point is below the part)")
    elif bottom >= r_level - SAME_POINT:
        word = "Z" + vals["Z"].text if "Z" in vals else ("R" + vals["R"].text if "R" in vals else gname)
        raise err(word, f"hole bottom Z {fmt_number(bottom * u)} {unit_name} is not below the R point "
                  f"{fmt_number(r_level * u)} {unit_name}", "Z below R (the cycles drill towards -Z; under G91 "
                  "R counts from the initial level and Z from the R point)")
    assert st.cycle is not None
    if st.cycle in (73, 83) and st.cycle_q is None:
        raise err(gname, f"{gname} without a peck depth Q", "Q > 0 on this or an earlier cycle block")
    if st.cycle in (76, 87):
        if st.cycle_q is None:
            raise err(gname, f"{gname} without a shift amount Q", "Q > 0 (the tool shift after the spindle "
                      "orientation) on this or an earlier cycle block")
        if st.direction != 1:
            raise err(gname, f"boring cycle {gname} without the spindle turning clockwise",
                      f"M3 S<rpm> before {gname} (FANUC orients the spindle and restarts it clockwise)")
    pitch, rigid, tap_per_rev = 0.0, False, 0.0
    if st.cycle in TAPPING:
        rigid = start_tapping(st, st.cycle, gname, vals, line, err, st.settings.cycles.rigid_always, out)
        feed, pitch, tap_per_rev = tap_feed(st, err, gname)
        per_rev = 0.0  # the tapping blocks carry their own feed per revolution
    else:
        feed, per_rev = block_feed(st, err, gname, f"canned cycle {gname}")
    pecks = 1 if st.cycle not in (73, 83) else math.ceil((r_level - bottom) / st.cycle_q - 1e-9)
    moves = repeat * (3 * pecks + 4)
    if moves > MAX_CYCLE_MOVES:
        raise err("Q" + vals["Q"].text if "Q" in vals else gname,
                  f"the cycle would expand to {moves} moves ({repeat} holes x {pecks} pecks)",
                  f"at most {MAX_CYCLE_MOVES} moves per block (a larger Q or a smaller K)")
    off = st.work_offset()
    tool = st.tool_length()
    z_off = off[2] + tool
    if st.xf.active:  # Z scaled about the scaling centre (check_cycle: not mirrored, not rotated)
        levels = (z_work(st, st.cycle_initial) + z_off, z_work(st, r_level) + z_off, z_work(st, bottom) + z_off)
    else:
        levels = (st.cycle_initial + z_off, r_level + z_off, bottom + z_off)
    for _ in range(repeat):
        if st.xf.engaged:  # G16 polar hole position and/or G51.1/G51/G68 transforms
            targets, absolute = program_targets(st, vals, err, "XY")
            x, y = advance(st, targets, absolute)[0][:2]
        else:
            for a in "XY":
                if a in vals:
                    i = AXIS_INDEX[a]
                    v = vals[a].value * scale
                    st.prog[i] = v if st.absolute else st.prog[i] + v
            x, y = st.prog[0] + off[0], st.prog[1] + off[1]
        hole = Hole(code=st.cycle, line=line, x=x, y=y, initial=levels[0],
                    r_level=levels[1], bottom=levels[2], return_to_initial=st.return_initial, feed=feed,
                    feed_line=st.feed_line, peck=st.cycle_q, dwell=st.cycle_dwell,
                    spindle=(st.speed, st.direction, st.speed_line), pitch=pitch, rigid=rigid,
                    feed_per_rev=tap_per_rev)
        try:
            blocks, end = expand_hole(hole, tuple(st.machine), st.settings.cycles)  # type: ignore[arg-type]
        except CycleError as exc:
            raise err(exc.word, exc.problem, exc.expected) from None
        if per_rev:  # G95: the feed blocks keep their feed per revolution (spindle overrides rescale them)
            blocks = [replace(b, feed_per_rev=per_rev) if isinstance(b, Linear) else b for b in blocks]
        out.extend(blocks)
        st.machine = list(end)
        st.applied_tool = tool
        st.prog[2] = st.cycle_initial if (st.return_initial or st.cycle == 87) else r_level
