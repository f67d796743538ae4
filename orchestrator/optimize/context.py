"""What the optimiser varies: cutting lines, their feed and spindle genes, and where S words go.

Rules (documented for machinists)
---------------------------------
* **Cutting line**: a source line holding a feed move (G1/G2/G3) that removes
  at least ``min_removed_mm3`` of material in one reference run of the
  original program on the twin (removed volume = time integral of the
  cutting component's material removal rate over the time the NC kernel
  executes that line). Air moves, plunges outside the stock and rapids are
  not cutting lines, nor is a straight retract along +Z (a flat end mill
  moving up its own axis meets no material: what the reference run credits
  to it is the servo lag's tail of the cut before, which it cannot change),
  nor a straight plunge along -Z (a drilling cycle's feed, ``G1 Z-2.``): its
  end edges remove material (:mod:`fmus_src.cutting.axial`) but load the tool
  with thrust and torque only, not with the lateral load ``fc`` the search
  limits, so a gene there would only run to the top of the feed range.
* **Genes**: one feed (mm/min) and one spindle speed (rpm) per cutting line,
  keys ``L0042.feed`` and ``L0042.spindle`` (``0042`` = 1-based line of the
  program file), on a grid of ``feed_step`` (10 mm/min) and ``spindle_step``
  (50 rpm) within the ranges. When a cutting line runs under G20 (inch), the
  feed grid is ``feed_step_in_per_min`` (0.1 in/min = 2.54 mm/min) instead,
  so the written in/min F words are round numbers and read back exactly as
  the genes (mm/min) say.
* **Tapping lines** (G84/G74: F = pitch x S) are never cutting lines; one whose F is modal (G94) is pinned
  (:mod:`.tapping`).
* **Non-cutting feed lines keep their feed**: a non-cutting feed line that
  would inherit a changed F modally from a cutting line gets its original F
  written explicitly (a "pin").
* **Where the S word goes** (``spindle_line``): the spindle speed of cutting
  line L must be in effect when L starts. If L directly follows another
  cutting line, S is written on L. Otherwise it is written at the start of the
  non-cutting stretch before L (on the original S word of that stretch if it
  has one, else on its first block line), so that the spindle ramps while the
  tool retracts, rapids and plunges; only the remainder of the ramp (the NC
  kernel's speed-arrival wait) costs time.
* **Which words are written** (:meth:`ProblemContext.words_for`): an S (F)
  word only where it changes something. A line without an S (F) word of its
  own gets one only when the value differs from the spindle speed (modal F)
  in effect there in the written program in at least one run of the line
  (subprograms, loops: the NC kernel's per-run view,
  :func:`fmus_src.nck.overrides.modal_before`); an S (F) word of the
  program keeps its text when its value is unchanged. A word left out would
  repeat the value in effect, so the written program runs exactly as the
  evaluated one, where every S-word line and every cutting line carries an
  override (an S command that repeats the speed in effect is skipped by the
  NC kernel's planner: it neither stops the path nor waits).
* **Feed per revolution (G95)**: the feed gene stays mm/min. The F word
  written on a G95 cutting line is ``gene / S`` (S = the line's spindle
  gene, in effect on every run of it) on the ``feed_step_mm_per_rev`` grid
  (0.001 mm/rev; ``feed_step_in_per_rev``, 0.0001 in/rev, under G20), kept
  so that ``F x S`` stays within the feed range where the grid allows; the
  feed in effect is that word x S, as the NC kernel computes every G95
  feed. Pins on G95 lines keep their mm/rev (in/rev).
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field

import numpy as np

from fmus_src.cutting.table import EngagementTable

from fmus_src.nck.blocks import (
    Arc, Block, Linear, Program, ProgramEnd, ProgramStop, SpindleSpeed, SpindleStop, ToolChange,
)
from fmus_src.nck.overrides import apply_overrides, modal_before
from fmus_src.nck.settings import INCH, MM, RPM
from fmus_src.nck.writer import MM_PER_INCH, feed_per_rev_word_value, feed_word_value, rewrite_program

from ..case import Case
from .errors import OptimizeError

RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)
MM_PER_MIN_PER_M_S = 60000.0


@dataclass(frozen=True)
class Ranges:
    """Search ranges and the machinist's grid.

    Attributes
    ----------
    feed_mm_per_min : (float, float)
        Feed range (the paper: 100–500 mm/min).
    spindle_rpm : (float, float)
        Spindle speed range (the paper: 1000–8000 rpm).
    feed_step : float
        Feed grid, mm/min.
    spindle_step : float
        Spindle grid, rpm.
    feed_step_in_per_min : float
        Feed grid of programs whose cutting lines run under G20, in/min.
    feed_step_mm_per_rev : float
        Grid of the F words written on G95 (feed per revolution) cutting lines under G21, mm/rev.
    feed_step_in_per_rev : float
        The same under G20, in/rev.
    """

    feed_mm_per_min: tuple[float, float] = (100.0, 500.0)
    spindle_rpm: tuple[float, float] = (1000.0, 8000.0)
    feed_step: float = 10.0
    spindle_step: float = 50.0
    feed_step_in_per_min: float = 0.1
    feed_step_mm_per_rev: float = 0.001
    feed_step_in_per_rev: float = 0.0001

    def __post_init__(self) -> None:
        if not (math.isfinite(self.feed_step_in_per_min) and self.feed_step_in_per_min > 0):
            raise OptimizeError(f"the inch feed grid step must be positive, got {self.feed_step_in_per_min} in/min")
        for name, value, unit in (("feed-per-revolution", self.feed_step_mm_per_rev, "mm/rev"),
                                  ("inch feed-per-revolution", self.feed_step_in_per_rev, "in/rev")):
            if not (math.isfinite(value) and value > 0):
                raise OptimizeError(f"the {name} grid step must be positive, got {value} {unit}")
        for name, (lo, hi), step in (("feed range", self.feed_mm_per_min, self.feed_step),
                                     ("spindle range", self.spindle_rpm, self.spindle_step)):
            if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= hi and step > 0):
                raise OptimizeError(f"{name} must be 0 < low <= high with a positive grid step, got {lo}, {hi}, {step}")
            if math.ceil(lo / step - 1e-9) * step > hi + 1e-9:
                raise OptimizeError(f"{name} {lo}..{hi} holds no multiple of {step}")


@dataclass
class ProblemContext:
    """Everything needed to evaluate an individual (picklable; sent to worker processes).

    Attributes
    ----------
    case : Case
        Stock, tool, machine; ``case.program`` names the file.
    program_text : str
        The original program.
    lines : ndarray of int, shape (L,)
        Cutting lines (1-based), in program order.
    spindle_lines : ndarray of int, shape (L,)
        Line that carries the S word of each cutting line.
    pinned_feeds : dict[int, float]
        Non-cutting feed lines whose original feed is written explicitly, mm/min (mm/rev on ``per_rev_lines``).
    original_feed, original_spindle : ndarray, shape (L,)
        Feed (mm/min; F x S on a G95 line) and spindle speed (rpm) of each cutting line in the original program.
    ranges : Ranges
        Search ranges and grid.
    load_limit_N : float
        Cutting load limit Flim, N.
    removed_mm3 : dict[int, float]
        Removed volume per feed line in the reference run, mm3 (how lines were classified).
    step : float
        Communication step of the twin, s.
    time_limit_s : float
        Simulated-time limit per evaluation, s.
    original_load_N : ndarray, shape (L,)
        Largest cutting load of each cutting line in the reference run, N (seeds the chip-load scaling).
    engagement : EngagementTable or None
        Cutter–workpiece engagement along the program's path, computed once
        (F and S change the timing, not the path); every evaluation then runs
        the twin's path-mode cutting load. None: Z-map cutting per member.
    inch_lines : frozenset of int
        Cutting and pinned feed lines under G20: their F words are written, and their overrides converted, in
        in/min (:func:`fmus_src.nck.writer.feed_word_value`), or in/rev under G95.
    per_rev_lines : frozenset of int
        Cutting and pinned feed lines under G95 (every run): their F words are feeds per revolution, and
        ``pinned_feeds`` holds mm/rev for them.
    program : Program or None
        The interpreted original program (the NC kernel's per-run view, :meth:`words_for`); None: interpreted
        on first use.
    search_model_note : str
        Why the search runs on the Z-map model although the path mode was asked for (the path mode failed on
        the original program, naming the line); empty otherwise. ``report.json`` lists it in ``notes``.
    """

    case: Case
    program_text: str
    lines: np.ndarray
    spindle_lines: np.ndarray
    pinned_feeds: dict[int, float]
    original_feed: np.ndarray
    original_spindle: np.ndarray
    ranges: Ranges
    load_limit_N: float
    removed_mm3: dict[int, float] = field(default_factory=dict)
    step: float = 1e-3
    time_limit_s: float = 3600.0
    original_load_N: np.ndarray = field(default_factory=lambda: np.zeros(0))
    engagement: EngagementTable | None = field(default=None, repr=False, compare=False)
    inch_lines: frozenset[int] = frozenset()
    per_rev_lines: frozenset[int] = frozenset()
    program: Program | None = field(default=None, repr=False, compare=False)
    search_model_note: str = field(default="", compare=False)

    @property
    def inch(self) -> bool:
        """A cutting line runs under G20: the feed grid is ``ranges.feed_step_in_per_min``."""
        return any(int(line) in self.inch_lines for line in self.lines.tolist())

    @property
    def feed_step(self) -> float:
        """Feed grid of the genes, mm/min (10, or 0.1 in/min = 2.54 mm/min for an inch program)."""
        r = self.ranges
        return r.feed_step_in_per_min * MM_PER_INCH if self.inch else r.feed_step

    def feed_word(self, line: int, feed_mm_per_min: float) -> float:
        """The F word written on ``line`` for a feed in mm/min (in/min under G20), as read back."""
        return feed_word_value(feed_mm_per_min, int(line) in self.inch_lines)

    def feed_per_rev_word(self, line: int, feed_mm_per_min: float, spindle_rpm: float) -> float:
        """The F word written on G95 cutting line ``line`` for a feed gene (mm/min) at its spindle gene (rpm).

        ``gene / S`` in mm/rev (in/rev under G20), rounded half up to the grid (``Ranges.feed_step_mm_per_rev``
        or ``feed_step_in_per_rev``) and kept within the grid values whose feed ``F x S`` lies in the feed range
        (when there is one), at least one grid step.

        Parameters
        ----------
        line : int
            The G95 line (1-based).
        feed_mm_per_min : float
            Feed gene, mm/min.
        spindle_rpm : float
            Spindle gene of the line, rpm (in effect on every run of it).

        Returns
        -------
        float
            The word as the lexer reads it back: mm/rev, in/rev under G20.
        """
        inch = int(line) in self.inch_lines
        r = self.ranges
        step = r.feed_step_in_per_rev if inch else r.feed_step_mm_per_rev
        per_unit = float(spindle_rpm) * (MM_PER_INCH if inch else 1.0)  # mm/min per (in or mm)/rev
        q = math.floor(float(feed_mm_per_min) / per_unit / step + 0.5)
        lo = math.ceil(r.feed_mm_per_min[0] / per_unit / step - 1e-9)
        hi = math.floor(r.feed_mm_per_min[1] / per_unit / step + 1e-9)
        if lo <= hi:
            q = min(max(q, lo), hi)
        word = max(q, 1) * step
        return feed_per_rev_word_value(word * MM_PER_INCH if inch else word, inch)

    @property
    def n_lines(self) -> int:
        """Number of cutting lines L."""
        return int(len(self.lines))

    @property
    def keys(self) -> list[str]:
        """Readable gene names ``L0042.feed``, ``L0042.spindle`` (feed, spindle per line)."""
        width = max(4, len(str(int(self.lines.max())))) if self.n_lines else 4
        out = []
        for line in self.lines.tolist():
            out += [f"L{line:0{width}d}.feed", f"L{line:0{width}d}.spindle"]
        return out

    def fingerprint(self) -> str:
        """Hash of program, genes and ranges (a checkpoint only resumes the same problem)."""
        h = hashlib.sha256(self.program_text.encode("utf-8"))
        r = self.ranges
        ranges = (f"Ranges(feed_mm_per_min={r.feed_mm_per_min!r}, spindle_rpm={r.spindle_rpm!r}, "
                  f"feed_step={r.feed_step!r}, spindle_step={r.spindle_step!r}, "
                  f"feed_step_in_per_min={r.feed_step_in_per_min!r})")  # as before G95 programs were optimised
        parts = [repr(self.lines.tolist()), repr(self.spindle_lines.tolist()), repr(sorted(self.pinned_feeds.items())),
                 ranges, repr(self.load_limit_N), repr(self.step), repr(sorted(self.inch_lines))]
        if self.per_rev_lines:
            parts += [repr(sorted(self.per_rev_lines)), repr(r.feed_step_mm_per_rev), repr(r.feed_step_in_per_rev)]
        h.update(("(" + ", ".join(parts) + ")").encode("utf-8"))  # the tuple's repr
        return h.hexdigest()[:16]

    # ------------------------------------------------------------------ genes <-> values
    def snap(self, feeds: np.ndarray, spindles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Round half up to the grid and clip into the ranges (shape kept)."""
        r = self.ranges
        step = self.feed_step
        f = np.clip(np.floor(np.asarray(feeds, float) / step + 0.5) * step,
                    math.ceil(r.feed_mm_per_min[0] / step - 1e-9) * step,
                    math.floor(r.feed_mm_per_min[1] / step + 1e-9) * step)
        s = np.clip(np.floor(np.asarray(spindles, float) / r.spindle_step + 0.5) * r.spindle_step,
                    math.ceil(r.spindle_rpm[0] / r.spindle_step - 1e-9) * r.spindle_step,
                    math.floor(r.spindle_rpm[1] / r.spindle_step + 1e-9) * r.spindle_step)
        return f, s

    def overrides(self, feeds: np.ndarray, spindles: np.ndarray
                  ) -> tuple[dict[int, object], dict[int, object], dict[int, object]]:
        """NC-kernel overrides for a population.

        Parameters
        ----------
        feeds : ndarray, shape (B, L)
            Feed per cutting line, mm/min.
        spindles : ndarray, shape (B, L)
            Spindle speed per cutting line, rpm.

        Returns
        -------
        feed, spindle, feed_per_rev : dict line -> ndarray (B,)
            In m/s (G94 lines), rad/s and m/rev (G95 lines), for :meth:`fmus_src.nck.NCKernel.set_overrides`.
        """
        feeds = np.atleast_2d(np.asarray(feeds, float))
        spindles = np.atleast_2d(np.asarray(spindles, float))
        batch = feeds.shape[0]
        # the interpreter's own conversions of the written words (F * MM / 60 or F * INCH / 60; under G95
        # F * MM or F * INCH; S * RPM), so an override equals the written word bit for bit (also in inch, where
        # the word is mm/min / 25.4, rounded)
        feed: dict[int, object] = {}
        per_rev: dict[int, object] = {}
        for line, f in self.pinned_feeds.items():
            if int(line) in self.per_rev_lines:
                per_rev[int(line)] = np.full(batch, self._si_per_rev(line, feed_per_rev_word_value(
                    f, int(line) in self.inch_lines)))
            else:
                feed[int(line)] = np.full(batch, self._si_feed(line, f))
        for i, line in enumerate(self.lines.tolist()):
            if int(line) in self.per_rev_lines:
                per_rev[int(line)] = np.array([self._si_per_rev(line, self.feed_per_rev_word(line, f, s))
                                               for f, s in zip(feeds[:, i].tolist(), spindles[:, i].tolist())])
            else:
                feed[int(line)] = np.array([self._si_feed(line, f) for f in feeds[:, i].tolist()])
        spindle: dict[int, object] = {int(line): spindles[:, i] * RPM
                                      for i, line in enumerate(self.spindle_lines.tolist())}
        return feed, spindle, per_rev

    def _si_feed(self, line: int, feed_mm_per_min: float) -> float:
        """Feed of ``line``'s written F word in m/s, converted as the interpreter converts it."""
        return self.feed_word(line, feed_mm_per_min) * (INCH if int(line) in self.inch_lines else MM) / 60.0

    def _si_per_rev(self, line: int, word: float) -> float:
        """Feed per revolution (m/rev) of a G95 F word ``word`` (mm/rev, in/rev under G20) on ``line``."""
        return word * (INCH if int(line) in self.inch_lines else MM)

    def original_feed_per_rev_word(self, line: int) -> float:
        """The F in effect on G95 line ``line`` in the original program (its first run), mm/rev (in/rev under
        G20), as written."""
        b = next(x for x in self.interpreted().blocks if isinstance(x, (Linear, Arc)) and x.line == int(line))
        return round(b.feed_per_rev / (INCH if int(line) in self.inch_lines else MM), 9)

    def interpreted(self) -> Program:
        """The interpreted original program (the twin's NC kernel reads it with the case's settings)."""
        if self.program is None:
            from ..twin import build_twin

            nck = build_twin(self.case, batch=1, program_text=self.program_text).nck
            nck.setup(0.0)
            self.program = nck.program_
        return self.program

    def words_for(self, feeds: np.ndarray, spindles: np.ndarray
                  ) -> tuple[dict[int, float], dict[int, float], dict[int, float]]:
        """The F and S words the written program of one individual carries (the module rule).

        Parameters
        ----------
        feeds, spindles : ndarray, shape (L,)
            mm/min and rpm.

        Returns
        -------
        feed_by_line, spindle_by_line, feed_per_rev_by_line : dict line -> value
            mm/min (G94 lines), rpm, mm/rev (G95 lines; the writer turns both feeds into in/min, in/rev under
            G20), as :func:`fmus_src.nck.writer.rewrite_program` takes them. Only lines whose word changes
            something: an S (F) word of the program with its value unchanged keeps its text, and a line
            without one gets one only where the value differs from the one in effect in at least one run.
        """
        f = np.ravel(np.asarray(feeds, float))
        s = np.ravel(np.asarray(spindles, float))
        feed, spindle, per_rev = self.overrides(f[None, :], s[None, :])
        program = self.interpreted()
        feed_before, speed_before = modal_before(program, 1, feed, spindle, per_rev)
        own_f, own_s = _own_words(program)
        keep_f = {line for over in (feed, per_rev) for line, v in over.items()
                  if _changes(float(v[0]), own_f.get(line), feed_before.get(line))}
        keep_s = {line for line, v in spindle.items()
                  if _changes(float(v[0]), own_s.get(line), speed_before.get(line))}
        feed_by_line: dict[int, float] = {}
        per_rev_by_line: dict[int, float] = {}
        for line, v in self.pinned_feeds.items():
            if int(line) in keep_f:
                (per_rev_by_line if int(line) in self.per_rev_lines else feed_by_line)[int(line)] = float(v)
        for i, line in enumerate(self.lines.tolist()):
            if int(line) not in keep_f:
                continue
            if int(line) in self.per_rev_lines:
                word = self.feed_per_rev_word(line, f[i], s[i])
                per_rev_by_line[int(line)] = word * MM_PER_INCH if int(line) in self.inch_lines else word
            else:
                feed_by_line[int(line)] = float(f[i])
        spindle_by_line = {int(line): float(s[i]) for i, line in enumerate(self.spindle_lines.tolist())
                           if int(line) in keep_s}
        return feed_by_line, spindle_by_line, per_rev_by_line

    def program_for(self, feeds: np.ndarray, spindles: np.ndarray) -> str:
        """The rewritten program of one individual (only F and S words change, see :meth:`words_for`).

        Parameters
        ----------
        feeds, spindles : ndarray, shape (L,)
            mm/min and rpm.
        """
        feed_by_line, spindle_by_line, per_rev_by_line = self.words_for(feeds, spindles)
        return rewrite_program(self.program_text, feed_by_line, spindle_by_line, file=str(self.case.program),
                               feed_per_rev_by_line=per_rev_by_line)

    def chip_load_feeds(self, spindles: np.ndarray, load_fraction: np.ndarray | float) -> np.ndarray:
        """Feeds that put each line at ``load_fraction`` of the limit at the given spindle speeds, mm/min.

        The cutting force of Eq. 10–13 is linear in the chip thickness, i.e. in the feed per tooth
        ``F / (S z)``, so at an unchanged engagement the load of line ``i`` scales as
        ``load_ref_i · (F / S) / (F_ref_i / S_ref_i)``. Lines that did not load the tool keep the top of the range.

        Parameters
        ----------
        spindles : ndarray, shape (..., L)
            Spindle speeds, rpm.
        load_fraction : float or ndarray broadcastable to (..., L)
            Target load as a fraction of the limit.
        """
        s = np.asarray(spindles, float)
        load = np.maximum(self.original_load_N, 1e-9)
        fz_ref = self.original_feed / np.maximum(self.original_spindle, 1e-9)
        target = np.asarray(load_fraction, float) * self.load_limit_N
        feeds = fz_ref * s * target / load
        return np.where(self.original_load_N > 1.0, feeds, self.ranges.feed_mm_per_min[1])

    def as_dict(self, feeds: np.ndarray, spindles: np.ndarray) -> dict[str, float]:
        """One individual as ``{"L0042.feed": 300.0, "L0042.spindle": 6000.0, ...}``."""
        x = np.empty(2 * self.n_lines)
        x[0::2], x[1::2] = np.ravel(feeds), np.ravel(spindles)
        return dict(zip(self.keys, x.tolist()))


def _own_words(program: Program) -> tuple[dict[int, set[float]], dict[int, set[float]]]:
    """Values (SI: m/s under G94, m/rev under G95, rad/s) of the F and S words each line sets itself, over all
    its runs (a macro expression may give several)."""
    feeds: dict[int, set[float]] = {}
    speeds: dict[int, set[float]] = {}
    for b in program.blocks:
        if isinstance(b, (Linear, Arc)) and b.feed_line == b.line:
            feeds.setdefault(b.line, set()).add(b.feed_per_rev if b.feed_per_rev > 0.0 else b.feed)
        elif isinstance(b, SpindleSpeed) and b.speed_line == b.line:
            speeds.setdefault(b.line, set()).add(b.speed)
    return feeds, speeds


def _changes(value: float, own: set[float] | None, before: np.ndarray | None) -> bool:
    """Whether a word of ``value`` on a line changes the written program.

    A line with a word of its own (values ``own``) keeps its text when the value is that word's in every run;
    a line without one needs the word unless ``value`` is already in effect in every run (``before``, one value
    per run, NaN where unknown).
    """
    if own is not None:
        return own != {value}
    if before is None or before.size == 0:
        return True
    return not bool(np.all(before == value))


def classify_lines(blocks: tuple[Block, ...], removed_mm3: dict[int, float], min_removed_mm3: float,
                   program: Program | None = None
                   ) -> tuple[list[int], list[int], dict[int, float], list[float], list[float]]:
    """Cutting lines, their S-word lines, feed pins and original values (see the module rules).

    Parameters
    ----------
    blocks : tuple of Block
        Interpreted original program (execution order, SI units; a subprogram's or loop's lines once per run).
    removed_mm3 : dict line -> mm3
        Removed volume per line in the reference run.
    min_removed_mm3 : float
        Threshold of a cutting line, mm3.
    program : Program, optional
        The interpreted program ``blocks`` come from. With it, every S-word line is checked to govern every
        run of its cutting line (:func:`_governed_spindle_lines`); a line that runs more than once (subprogram,
        loop) and whose S word placed before it would not, gets the S word on itself.

    Returns
    -------
    lines, spindle_lines, pins, feeds_mm_per_min, spindles_rpm
        ``pins`` maps a pinned line to its written feed: mm/min, or mm/rev on a G95 line. The feeds of G95
        cutting lines are feeds per minute (F x S).
    """
    feed_runs: dict[int, list[tuple[float, int]]] = {}  # every run of a feed line: (written feed, F-word line)
    per_minute: dict[int, float] = {}  # feed of a feed line's first run, mm/min (G95: F x S)
    for b in blocks:
        if isinstance(b, (Linear, Arc)):
            written = b.feed_per_rev * 1e3 if b.feed_per_rev > 0.0 else b.feed * MM_PER_MIN_PER_M_S  # mm/rev, mm/min
            feed_runs.setdefault(b.line, []).append((round(written, 6), b.feed_line))
            per_minute.setdefault(b.line, round(b.feed * MM_PER_MIN_PER_M_S, 6))
    feed_lines = {line: (per_minute[line], runs[0][1]) for line, runs in feed_runs.items()}
    tapping = {b.line for b in blocks if isinstance(b, Linear) and b.tap_pitch > 0.0}  # F tied to S: never genes
    axial = _axial_lines(blocks)
    cutting = sorted(line for line in feed_lines
                     if line not in tapping and line not in axial and removed_mm3.get(line, 0.0) >= min_removed_mm3)
    cut_set = set(cutting)
    # a G94 tapping line with a modal F gets it written (an F override of a cutting line in between would govern it)
    tap_modal = {b.line for b in blocks if isinstance(b, Linear) and b.tap_pitch > 0.0 and b.feed_per_rev == 0.0
                 and b.feed_line != b.line}
    # a non-cutting line that inherits F from a cutting line in ANY of its runs (a loop, a subprogram called
    # twice) gets its original F written; when its runs had different feeds, the lowest of them. "From a cutting
    # line" as the written program runs: also when the F it inherits was written before a cutting line without
    # an F word of its own, which gets one (the NC kernel's view, with a feed override on every cutting line)
    governed = _governed_feed_lines(program, cutting) if program is not None else set()
    pins = {line: min(f for f, _ in runs) for line, runs in feed_runs.items()
            if line not in cut_set and (any(src in cut_set for _, src in runs) or line in tap_modal
                                        or line in governed)}
    # spindle speed in effect at each cutting line, and where its S word goes
    speed_at: dict[int, float] = {}
    speed = 0.0
    for b in blocks:
        if isinstance(b, SpindleSpeed):
            speed = round(b.speed * RPM_PER_RAD_S, 6)  # the written value (the conversion leaves ~1e-12 rpm)
        elif isinstance(b, SpindleStop):
            speed = 0.0
        if b.line in cut_set and b.line not in speed_at:
            speed_at[b.line] = speed
    target_of = _spindle_targets(blocks, cut_set)
    if program is not None:
        target_of = _governed_spindle_lines(program, cutting, target_of)
    # values as written in the program (undo the SI round trip)
    return (cutting, [target_of[line] for line in cutting], {k: round(v, 6) for k, v in pins.items()},
            [round(feed_lines[line][0], 6) for line in cutting], [round(speed_at.get(line, 0.0), 6) for line in cutting])


def _governed_feed_lines(program: Program, cutting: list[int]) -> set[int]:
    """Feed lines whose feed, in at least one run, an F word on a cutting line would govern.

    Puts a feed override of an unmistakable value on every cutting line (m/s under G94, m/rev under G95: the
    NC kernel's modal rule, exactly as written F words act) and returns the lines of the feed blocks whose feed
    then changes. A cutting line run in both feed modes is left out (it is refused later, naming it).
    """
    modes: dict[int, set[bool]] = {}
    for b in program.blocks:
        if isinstance(b, (Linear, Arc)) and b.line in cutting:
            modes.setdefault(b.line, set()).add(b.feed_per_rev > 0.0)
    mark = {line: 1.0e3 + k for k, line in enumerate(cutting)}  # 1000 m/s or m/rev: no program's feed
    feed = {line: v for line, v in mark.items() if modes.get(line) == {False}}
    per_rev = {line: v for line, v in mark.items() if modes.get(line) == {True}}
    _, plain, _ = apply_overrides(program, 1)
    blocks, feeds, _ = apply_overrides(program, 1, feed, None, per_rev)
    return {b.line for i, b in enumerate(blocks)
            if isinstance(b, (Linear, Arc)) and not feeds[0, i] == plain[0, i]}


def _axial_lines(blocks: tuple[Block, ...]) -> set[int]:
    """Lines whose every feed move is a straight move along Z only (a retract or a plunge on the tool's axis).

    A flat end mill cuts with its periphery and its end face. Moving up its own axis neither meets material
    (the end face leaves it) nor moves the periphery sideways, so such a line removes nothing itself. Moving
    down it removes material with the end edges only (the axial chip): thrust and spindle torque, no lateral
    load ``fc`` (symmetric engagement), which the search limits; its F is left as written.
    """
    out: dict[int, bool] = {}
    for b in blocks:
        if isinstance(b, (Linear, Arc)):
            d = np.asarray(b.end, float) - np.asarray(b.start, float)
            along_z = isinstance(b, Linear) and d[2] != 0.0 and d[0] == 0.0 and d[1] == 0.0
            out[b.line] = out.get(b.line, True) and along_z
    return {line for line, z_only in out.items() if z_only}


def _spindle_targets(blocks: tuple[Block, ...], cut_set: set[int]) -> dict[int, int]:
    """The S-word line of each cutting line from its first run, in execution order (the module rule).

    The stretch before a cutting line is what runs between the previous cutting block and it. Its last spindle
    command (S, M5, M6) decides: an S word takes the new speed; M5 or M6 leave it on the cutting line; without
    one, the stretch's first block that is not an M0/M1 program stop takes it. Two cutting lines never share a
    target line (both then get their own).
    """
    target_of: dict[int, int] = {}
    stretch_start = 0
    for i, b in enumerate(blocks):
        if b.line not in cut_set:
            continue
        if b.line not in target_of:
            stretch = [s for s in blocks[stretch_start:i] if s.line != b.line]
            target = b.line
            barrier = None
            for s in stretch:
                if isinstance(s, (SpindleSpeed, SpindleStop, ToolChange)):
                    barrier = s
            if isinstance(barrier, SpindleSpeed):
                target = barrier.line
            elif barrier is None:
                first = next((s.line for s in stretch if not isinstance(s, (ProgramStop, ProgramEnd))), None)
                target = b.line if first is None else first
            target_of[b.line] = target
        stretch_start = i + 1
    claimed: dict[int, int] = {}
    for line, target in target_of.items():
        claimed[target] = claimed.get(target, 0) + 1
    return {line: (target if claimed[target] == 1 else line) for line, target in target_of.items()}


def _governed_spindle_lines(program: Program, cutting: list[int], target_of: dict[int, int]) -> dict[int, int]:
    """Move the S word of a cutting line onto the line itself wherever its S-word line does not govern every
    one of its runs (a subprogram called from several places, a loop, a target line that also runs elsewhere).

    Marks each S-word line with its own speed through the NC kernel's overrides (modal in execution order,
    exactly as the written words act) and checks the speed in effect at every feed block of every cutting line.
    """
    target_of = dict(target_of)
    cut_set = set(cutting)
    for _ in range(len(cutting) + 1):
        marks = {target_of[line]: 1.0e9 + k for k, line in enumerate(cutting)}
        blocks, _, speeds = apply_overrides(program, 1, None, marks)
        mark_of = {line: marks[target_of[line]] for line in cutting}
        bad: set[int] = set()
        current = math.nan
        for i, b in enumerate(blocks):
            if isinstance(b, SpindleSpeed):
                current = float(speeds[0, i])
            elif isinstance(b, (Linear, Arc)) and b.line in cut_set and current != mark_of[b.line]:
                bad.add(b.line)
        bad = {line for line in bad if target_of[line] != line}
        if not bad:
            break
        for line in bad:
            target_of[line] = line
    return target_of


def check_context(ctx: ProblemContext) -> None:
    """Refuse problems the optimiser cannot treat (no cutting line, spindle stopped on a cutting line)."""
    if ctx.n_lines == 0:
        stock = ctx.case.stock
        box = "" if stock is None else (f" from the stock {[float(v) for v in stock.min_mm]}.."
                                        f"{[float(v) for v in stock.max_mm]} mm")
        raise OptimizeError(
            f"{ctx.case.program}: no cutting line found: no feed move removes material{box} in the reference run "
            "(a plunge along Z, as a drilling cycle, removes none in the twin); expected at least one G1/G2/G3 "
            "move through the stock: check the case's [stock] and the program's work offsets"
        )
    lo, hi = ctx.ranges.feed_mm_per_min
    if ctx.inch and math.ceil(lo / ctx.feed_step - 1e-9) * ctx.feed_step > hi + 1e-9:
        raise OptimizeError(f"{ctx.case.program}: inch program (G20): feed range {lo:g}..{hi:g} mm/min "
                            f"({lo / MM_PER_INCH:.4g}..{hi / MM_PER_INCH:.4g} in/min) holds no multiple of "
                            f"{ctx.ranges.feed_step_in_per_min:g} in/min")
    stopped = ctx.lines[ctx.original_spindle <= 0.0]
    if stopped.size:
        raise OptimizeError(f"{ctx.case.program}:{int(stopped[0])}: cutting line with the spindle stopped; "
                            "expected S and M3/M4 before the first cut")
