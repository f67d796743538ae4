"""Work offsets of a block: G54-G59, G54.1 Pn (G54 Pn), Haas G154 Pn / G110-G129 and G10 data input.

Conventions
-----------
* Additional work coordinate systems (FANUC 0i-MF/31i-B option):
  ``G54.1 P<n>`` and its alternate form ``G54 P<n>``, n = 1..48, select a
  work offset like G54-G59 (modal, group 14); its value is
  ``work_offsets[additional_offset_key(n)]`` (key 1000 + n, the default
  work zero ``-machine_zero`` when missing, like G54-G59). G54.1 without
  P, P outside 1..48 or with a decimal point, and G54.1 in a block where
  P means something else (G4, G10, M98, a canned cycle) are errors (FANUC takes G54.1 without P as P1; the twin asks for
  it). ``G54 P<n>`` in such a block is plain G54 (P keeps its meaning there).
* Haas additional work offsets (Haas mill operator's manual, G154, group
  12): ``G154 P<n>``, n = 1..99, and its aliases G110..G129 (= G154
  P1..P20) select the additional work offset n. They share one table with
  FANUC's G54.1 Pn: G154 Pn, G54.1 Pn (n <= 48) and G110 + n - 1 (n <= 20)
  are the same offset, key 1000 + n (:func:`.settings.g154_offset_key`).
  G54.1 keeps FANUC's 48 (the 0i-MF option the twin models; P49 is an
  alarm there); G154 takes Haas' 99, and ``G10 L20 P<n>`` sets n = 1..99
  (on a Haas G10 L20 sets the G154 offsets; on FANUC P49..P99 would need
  the 300-set option). G154 without P, P outside 1..99 or with a decimal
  point, and G154 in a block where P means something else are errors, as
  for G54.1.
* External workpiece zero point offset (``work_offsets[EXTERNAL_OFFSET]``,
  key 0, set by ``G10 L2 P0``): added to every work coordinate system
  (G54-G59 and G54.1 Pn), never to G53/G28 machine positions.
* G10 programmable data input (non-modal, no motion; tool offset memory C):
  ``G10 L2 P<p> X Y Z`` sets the work offset G54..G59 (p = 1..6) or the
  external offset (p = 0); ``G10 L20 P<n> X Y Z`` sets G54.1 Pn / G154 Pn;
  ``G10 L10/L11 P<n> R`` the geometry/wear of tool length offset Hn and
  ``G10 L12/L13 P<n> R`` the geometry/wear of tool radius offset Dn (the
  offset used is geometry + wear; :attr:`InterpreterSettings.tool_lengths`
  and ``tool_radii`` are the geometry, the wear starts at 0). Under G90 the
  given values are set, under G91 added; axes not given keep their value;
  values in the unit in effect (G20/G21). The G54..G59/G54.1 values are the
  machine coordinates of the work zero (FANUC), turned into the axis frame
  with :attr:`.settings.InterpreterSettings.machine_zero`; a work system not
  yet set starts from the default work zero ``-machine_zero`` (G91 adds to
  it). The change takes effect like the
  other offset changes (:mod:`.modal`): a changed active work offset shifts the programmed
  coordinates of the current position, a changed tool length is applied by
  the next Z move, and a changed active D radius is used for the end vector of the
  next move under G41/G42 (:mod:`.radius_offset`). Other L,
  a missing P or data word, P out of range, words of the other form, a
  motion G code in the block and G10 in canned-cycle mode are errors.
"""
from __future__ import annotations

from .blocks import AXIS_INDEX
from .codes import GWords, ValueWords
from .errors import ErrorFactory
from .modal import ModalState
from .settings import EXTERNAL_OFFSET, N_ADDITIONAL_OFFSETS, N_HAAS_OFFSETS, g154_offset_key

#: Haas aliases G110..G129 of G154 P1..P20 (first, last code).
HAAS_ALIASES = (110, 129)

#: G10 L numbers: L -> what it sets.
G10_L = {2: "work offset G54-G59 (P1-P6) or the external offset (P0)",
         20: "additional work offset G54.1 Pn / G154 Pn",
         10: "tool length geometry H", 11: "tool length wear H", 12: "tool radius geometry D",
         13: "tool radius wear D"}


def select_work_offset(st: ModalState, gs: GWords, vals: ValueWords, call: str | None, err: ErrorFactory) -> None:
    """Make the block's G54-G59 / G54.1 Pn / G54 Pn / G154 Pn / G110-G129 the active work offset (``call``:
    ``"M98"`` or ``"M97"`` when the block calls a subprogram, else None).

    A change shifts the programmed coordinates of the current position (:meth:`ModalState.shift_work`).
    """
    new = work_key(st, gs, vals, call, err)
    code = gs["work offset"][0]
    st.work_code = 54.1 if code == 54 and new > 1000 else float(code)  # G54 P<n> is G54.1 P<n>
    if new != st.work:
        st.work = new
        st.shift_work()


def work_key(st: ModalState, gs: GWords, vals: ValueWords, call: str | None, err: ErrorFactory) -> int:
    """Work-offset key selected by the block's G54-G59 / G54.1 Pn / G54 Pn / G154 Pn / G110-G129 (pops the P
    word it uses).

    ``G54 P<n>`` is the alternate form of ``G54.1 P<n>`` unless P belongs to G4, G10, M97/M98 or a canned cycle
    in the block; G54.1 and G154 need their P and may not share the block with them. G110..G129 take no P.
    """
    code, gw = gs["work offset"]
    other = None
    drill = "canned cycle" in gs and gs["canned cycle"][0] != 80
    cancel = "motion" in gs or gs.get("canned cycle", (None,))[0] == 80
    if "non-modal" in gs:
        other = "G" + gs["non-modal"][1].text
    elif call is not None:
        other = call
    elif drill:
        other = "G" + gs["canned cycle"][1].text
    elif st.cycle is not None and not cancel:
        other = f"canned-cycle mode G{st.cycle}"
    if HAAS_ALIASES[0] <= code <= HAAS_ALIASES[1]:  # G110..G129 = G154 P1..P20
        return g154_offset_key(int(code) - HAAS_ALIASES[0] + 1)
    top = N_HAAS_OFFSETS if code == 154 else N_ADDITIONAL_OFFSETS
    if code in (54.1, 154):
        name = "G" + gw.text
        if other is not None:
            raise err(name, f"{name} and {other} in one block (the P word would have two meanings)",
                      f"{name} P<n> in a block without G4, G10, M97/M98 or a canned cycle")
        if "P" not in vals:
            raise err(name, f"{name} without P (the number of the additional work coordinate system)",
                      f"{name} P1 .. {name} P{top}")
    elif code != 54 or "P" not in vals or other is not None:
        return int(code)
    p = vals.pop("P")
    if p.has_point or not 1 <= p.value <= top:
        raise err("P" + p.text, f"additional work coordinate system P{p.text} does not exist",
                  f"P1..P{top} (integers) with G{gw.text}")
    return g154_offset_key(int(p.value))


def program_data(st: ModalState, gs: GWords, vals: ValueWords, err: ErrorFactory) -> None:
    """G10 programmable data input: L2/L20 work offsets, L10-L13 tool offsets (memory C); see the module
    docstring. G90 sets the values, G91 adds them."""
    if "motion" in gs:
        raise err("G" + gs["motion"][1].text, "G10 and a motion G code in one block",
                  "G10 with L, P and its data words only")
    forms = f"G10 L2 P0-P6 X Y Z, G10 L20 P1-P{N_HAAS_OFFSETS} X Y Z, G10 L10/L11/L12/L13 P<n> R"
    if "L" not in vals:
        raise err("G10", "G10 without L (which data to set)", forms)
    lw = vals["L"]
    if lw.has_point or lw.value not in G10_L:
        raise err("L" + lw.text, f"G10 L{lw.text} is not supported", forms)
    ell = int(lw.value)
    if "P" not in vals:
        raise err(f"L{lw.text}", f"G10 L{ell} without P (the number of the {G10_L[ell]})", forms)
    pw = vals["P"]
    work = ell in (2, 20)
    data = "XYZ" if work else "R"
    for a in "XYZIJKRQ":
        if a in vals and a not in data:
            raise err(a + vals[a].text, f"word {a} in a G10 L{ell} block", f"G10 L{ell} P<n> with {' '.join(data)}")
    given = [a for a in data if a in vals]
    if not given:
        raise err(f"L{lw.text}", f"G10 L{ell} without data", f"G10 L{ell} P<n> with {' or '.join(data)}")
    if ell == 2:
        top, first = 6, 0
    elif ell == 20:  # G54.1 Pn (FANUC, n <= 48) and Haas G154 Pn (n <= 99): one table
        top, first = N_HAAS_OFFSETS, 1
    else:
        top, first = len(st.lengths if ell in (10, 11) else st.radii), 1
    if pw.has_point or not first <= pw.value <= top:
        raise err("P" + pw.text, f"G10 L{ell} P{pw.text}: {G10_L[ell]} number P{pw.text} does not exist",
                  f"P{first}..P{top} (integers)")
    p = int(pw.value)
    if work:
        key = g154_offset_key(p) if ell == 20 else (EXTERNAL_OFFSET if p == 0 else 53 + p)
        xyz = list(st.offsets.get(key, (0.0, 0.0, 0.0)))  # axis-frame shifts; missing: the default work zero
        for a in given:
            i = AXIS_INDEX[a]
            v = vals[a].value * st.scale
            if not st.absolute:
                xyz[i] += v
            else:  # G90: a work zero in machine coordinates (the external offset: a shift)
                xyz[i] = v if key == EXTERNAL_OFFSET else st.settings.machine_to_axis(i, v)
        st.offsets[key] = tuple(xyz)  # type: ignore[assignment]
        if key in (st.work, EXTERNAL_OFFSET):
            st.shift_work()
        return
    table = st.lengths if ell in (10, 11) else st.radii
    part = 0 if ell in (10, 12) else 1  # geometry, wear
    v = vals["R"].value * st.scale
    table[p - 1][part] = v if st.absolute else table[p - 1][part] + v
