"""Identification of the twin's parameters from recordings (Sim & Lee 2023, Sections 2.2-2.4).

* :func:`identify_friction` — Stribeck friction per axis and direction from
  constant-velocity segments detected automatically (Eq. 3-6);
* :func:`identify_servo` — scale factors Spp, Svp, Svi by replaying the
  closed loop on the recorded reference (Eq. 7-9);
* :func:`identify_cutting` — Kt, Ke with the twin's cutting engagement on the
  recorded tool path (Eq. 14-16).

Each takes case folders, offers ``method="default"`` (fast, accurate) and
``method="paper-ga"`` (the paper's genetic algorithm), and returns a fit
object whose ``write(out)`` produces ``machine.toml``, ``report.json`` and
plots. :func:`identify` runs one of them with checkpoints in
``out/checkpoints/`` and ``resume=True`` continues a killed job with the
same result (:mod:`.journal`).
"""
from __future__ import annotations

from .closed_loop import ReplayResult, replay
from .cutting import CuttingFit, identify_cutting
from .errors import IdentificationError
from .friction import FrictionFit, FrictionIdentifier, identify_friction
from .journal import Journal, job_identity
from .segments import Segment, SegmentSettings, find_segments
from .servo import ServoFit, identify_servo
from .stribeck import StribeckFit, fit_stribeck, stribeck_curve
from .synthetic import Imperfections, degrade

__all__ = [
    "CuttingFit", "FrictionFit", "FrictionIdentifier", "IdentificationError", "Imperfections", "Journal",
    "ReplayResult",
    "Segment", "SegmentSettings", "ServoFit", "StribeckFit", "degrade", "find_segments", "fit_stribeck",
    "identify", "identify_cutting", "identify_friction", "identify_servo", "replay", "stribeck_curve",
]


def identify(kind: str, cases, out=None, method: str = "default", seed: int = 0, resume: bool = False, **options):
    """Run one identification (``kind`` = ``"friction"``, ``"servo"`` or ``"cutting"``) and optionally write it.

    With ``out``, every expensive evaluation (GA generation, least-squares
    evaluation, batched cutting run, Stribeck fit) is checkpointed atomically
    in ``out/checkpoints/`` as it finishes; ``resume=True`` continues a killed
    job from them and gives the same result as an uninterrupted run (see
    :mod:`orchestrator.identify.journal`).

    Parameters
    ----------
    kind : str
    cases : iterable of case folders
    out : str or Path, optional
        Result folder (``machine.toml``, ``report.json``, plots, ``checkpoints/``).
    method : {"default", "paper-ga"}
    seed : int
    resume : bool
        Continue the interrupted job whose checkpoints are in ``out`` (same cases, method, seed, options).
    **options
        Passed to the identifier (``axes=``, ``machine=`` for servo, ...).

    Returns
    -------
    FrictionFit, ServoFit or CuttingFit

    Raises
    ------
    IdentificationError
        Unknown kind, ``resume`` without ``out``, a checkpoint of another job, or a problem of the data.
    """
    from .data import as_case

    functions = {"friction": identify_friction, "servo": identify_servo, "cutting": identify_cutting}
    if kind not in functions:
        raise IdentificationError(f"unknown identification {kind!r}; expected one of {sorted(functions)}")
    cases = [as_case(c) for c in cases]
    journal = Journal(out, job_identity(kind, cases, method, seed, options) if out is not None else None, resume)
    fit = functions[kind](cases, method=method, seed=seed, journal=journal, **options)
    if out is not None:
        fit.files_ = fit.write(out)
    return fit
