"""Checkpoints of an identification: a journal of its expensive evaluations, resumable after a kill.

Every identifier is deterministic for given cases, settings and seed: the
GA (pymoo, seeded), the trust-region least squares and the spindle-phase
scans ask for exactly the same evaluations in the same order when run again.
So instead of freezing each optimiser's internals, the job records the
*results* of its expensive evaluations (a GA generation's batched
closed-loop replay, one least-squares evaluation, one batched cutting run, one
Stribeck fit) in a :class:`Journal`:

* after each new evaluation the journal writes the entries not yet on disk to
  ``DIR/checkpoints/identify_00001.pkl``, ``..._00002.pkl``, ... atomically
  (:mod:`orchestrator.checkpoint`), so a job killed at any moment keeps every
  evaluation finished before the kill;
* ``resume=True`` reads them back; the identifier then runs from the start,
  every evaluation already journaled is answered from the journal (a
  dictionary look-up instead of a simulation), and the job continues where it
  was killed. The final result equals the uninterrupted run's bit for bit:
  the journal returns the very numbers the evaluation produced.

Each file carries the job's *identity* (kind, method, seed, options and a
SHA-256 of every input file: ``case.toml``, program, recording, machine); a
checkpoint of another job is refused with :class:`IdentificationError`. A job
started without ``resume`` removes the journal files of an earlier job in the
same folder.
"""
from __future__ import annotations

import dataclasses
import hashlib
import struct
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

import numpy as np

from ..case import Case
from ..checkpoint import checkpoint_dir, read_checkpoints, write_checkpoint
from ..machine import Machine
from .errors import IdentificationError

FORMAT = 1
#: File names of the journal in ``DIR/checkpoints/`` (the number sorts in write order).
PATTERN = "identify_*.pkl"


def _feed(h: "hashlib._Hash", obj: Any) -> None:
    """Feed a canonical byte form of ``obj`` (arrays, numbers, strings, containers) into ``h``."""
    if isinstance(obj, np.ndarray):
        arr = np.ascontiguousarray(obj)
        h.update(b"A" + arr.dtype.str.encode() + repr(arr.shape).encode() + arr.tobytes())
    elif isinstance(obj, (bool, np.bool_)):
        h.update(b"B1" if obj else b"B0")
    elif isinstance(obj, (int, np.integer)):
        h.update(b"I" + str(int(obj)).encode())
    elif isinstance(obj, (float, np.floating)):
        h.update(b"F" + struct.pack("<d", float(obj)))
    elif isinstance(obj, str):
        h.update(b"S" + str(len(obj)).encode() + b":" + obj.encode())
    elif obj is None:
        h.update(b"N")
    elif isinstance(obj, (tuple, list)):
        h.update(b"L" + str(len(obj)).encode())
        for item in obj:
            _feed(h, item)
    elif isinstance(obj, Mapping):
        h.update(b"D" + str(len(obj)).encode())
        for k in sorted(obj, key=str):
            _feed(h, str(k))
            _feed(h, obj[k])
    elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        _feed(h, type(obj).__name__)
        _feed(h, dataclasses.asdict(obj))
    else:
        raise IdentificationError(f"journal: cannot key a {type(obj).__name__} ({obj!r}); expected arrays, numbers, "
                                  "strings or containers of them")


def digest(*parts: Any) -> str:
    """SHA-256 (hex) of the canonical byte form of ``parts``."""
    h = hashlib.sha256()
    _feed(h, parts)
    return h.hexdigest()


def _file_digest(path: str | Path | None) -> str | None:
    if path is None or not Path(path).is_file():
        return None
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _machine_digest(machine: Machine) -> str:
    return digest(repr(machine.values))


def _describe(value: Any) -> Any:
    """A picklable, comparable description of an identifier option (a Machine by its values' digest)."""
    if isinstance(value, Machine):
        return {"machine": _machine_digest(value)}
    if isinstance(value, (str, Path)) and Path(value).is_file():
        return {"file": str(value), "sha256": _file_digest(value)}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {type(value).__name__: dataclasses.asdict(value)}
    if isinstance(value, (list, tuple)):
        return [_describe(v) for v in value]
    return value


def job_identity(kind: str, cases: Iterable[Case], method: str, seed: int, options: Mapping[str, Any]) -> dict:
    """What must be equal for a checkpoint to belong to this job.

    Parameters
    ----------
    kind : str
        ``"friction"``, ``"servo"`` or ``"cutting"``.
    cases : iterable of Case
        The loaded cases (their files are hashed: ``case.toml``, program, recording; the machine by its values).
    method : str
    seed : int
    options : mapping
        The identifier's keyword options.
    """
    inputs = [{"case": str(c.source or c.folder), "case_toml": _file_digest(c.source),
               "program": _file_digest(c.program), "recording": _file_digest(c.recording),
               "machine": _machine_digest(c.machine)} for c in cases]
    return {"kind": kind, "method": method, "seed": int(seed),
            "options": {k: _describe(v) for k, v in sorted(options.items())}, "inputs": inputs}


class Journal:
    """Memo of an identification's expensive evaluations, checkpointed in ``out/checkpoints/``.

    Parameters
    ----------
    out : str or Path, optional
        Output folder of the job; None: no checkpoints, :meth:`memo` just evaluates.
    identity : dict, optional
        :func:`job_identity` of the job.
    resume : bool
        Load the journal of an interrupted run of the same job from ``out``.

    Raises
    ------
    IdentificationError
        ``resume`` without ``out``; a checkpoint of another job; checkpoint files none of which is readable.
    """

    def __init__(self, out: str | Path | None = None, identity: dict | None = None, resume: bool = False) -> None:
        self.out = Path(out) if out is not None else None
        self.identity = identity
        self.resumed_entries = 0
        self._entries: dict[str, Any] = {}
        self._unsaved: dict[str, Any] = {}
        self._files = 0
        if self.out is None:
            if resume:
                raise IdentificationError("resume needs the output folder of the interrupted job (--out)")
            return
        existing = sorted(checkpoint_dir(self.out).glob(PATTERN))
        if not resume:
            for path in existing:  # a new job: the journal of an earlier job in this folder must not leak in
                path.unlink()
            return
        states = read_checkpoints(self.out, PATTERN, FORMAT, IdentificationError)
        if existing and not states:
            raise IdentificationError(f"{checkpoint_dir(self.out)}: no readable checkpoint to resume from")
        for state in states:
            if state.get("identity") != identity:
                raise IdentificationError(
                    f"{state['path']}: the checkpoint belongs to another job (its {_difference(state.get('identity'), identity)} "
                    f"differ; checkpoint: {_summary(state.get('identity'))}); resume with the same cases, method, "
                    "seed and options, or use a new --out")
            self._entries.update(state["entries"])
        self.resumed_entries = len(self._entries)
        self._files = max((int(p.stem.rsplit("_", 1)[1]) for p in existing), default=0)

    def memo(self, stage: str, key: Any, compute: Callable[[], Any]) -> Any:
        """The journaled result of evaluation ``(stage, key)``, or ``compute()`` (then journaled and checkpointed).

        Parameters
        ----------
        stage : str
            What is evaluated (``"servo.residuals"``).
        key : arrays, numbers, strings or containers of them
            Everything the result depends on besides the job's identity.
        compute : callable
            Evaluates it; its result must be picklable and is returned unchanged (callers must not modify it).
        """
        if self.out is None:  # no checkpoints: nothing to keep
            return compute()
        k = digest(stage, key)
        if k in self._entries:
            return self._entries[k]
        value = compute()
        self._entries[k] = value
        self._unsaved[k] = value
        self.flush()
        return value

    def flush(self) -> None:
        """Write the entries not yet on disk to the next checkpoint file (atomically)."""
        if self.out is None or not self._unsaved:
            return
        self._files += 1
        write_checkpoint(self.out, f"identify_{self._files:05d}", {"identity": self.identity,
                                                                    "entries": self._unsaved}, FORMAT)
        self._unsaved = {}


def _difference(old: Any, new: Any) -> str:
    """Which parts of two identities differ (``"seed and input files"``)."""
    names = {"kind": "kind", "method": "method", "seed": "seed", "options": "options", "inputs": "input files"}
    if not isinstance(old, dict) or not isinstance(new, dict):
        return "identity"
    parts = [text for key, text in names.items() if old.get(key) != new.get(key)] or ["identity"]
    return " and ".join(parts)


def _summary(identity: Any) -> str:
    if not isinstance(identity, dict):
        return repr(identity)
    cases = ", ".join(str(i.get("case")) for i in identity.get("inputs", []))
    return (f"{identity.get('kind')} identification, method {identity.get('method')!r}, seed {identity.get('seed')}, "
            f"options {identity.get('options')}, cases {cases}")
