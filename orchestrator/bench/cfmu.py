"""The C-FMU benchmark fixture: a first-order lag FMU with one input and one output, built at run time.

:func:`build_lag_fmu` compiles ``lag_fmu/lag.c`` against the FMI 2.0 headers
that ship with fmpy and packs ``Lag.fmu``; :func:`lag_ring` instantiates four
of them as :class:`~orchestrator.fmu.FMUComponent` objects wired in a ring::

    a.y -> b.u -> c.u -> d.u -> a.u      (gains 1, 1, 1, k_last)

With ``tau y' = k u - y`` per stage the ring is linear; its exact discrete
solution is what the tests check the loops against.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tempfile
import zipfile
from pathlib import Path

import fmpy

from ..errors import CncTwinError
from ..system import System

SOURCE_DIR = Path(__file__).resolve().parent / "lag_fmu"
FMI_HEADERS = Path(fmpy.__file__).resolve().parent / "c-code"
#: Instance names of the ring, in signal-flow order.
RING = ("a", "b", "c", "d")


def build_lag_fmu(out_dir: str | Path | None = None) -> Path:
    """Compile and pack ``Lag.fmu`` (cached by source digest).

    Parameters
    ----------
    out_dir : str or Path, optional
        Folder for the FMU; a per-user folder in the temp directory by default.

    Returns
    -------
    Path
        The ``.fmu`` file.

    Raises
    ------
    CncTwinError
        No C compiler, or the compilation failed.
    """
    sources = [SOURCE_DIR / "lag.c", SOURCE_DIR / "modelDescription.xml"]
    digest = hashlib.sha1(b"".join(p.read_bytes() for p in sources)).hexdigest()[:12]
    out = Path(out_dir) if out_dir is not None else Path(tempfile.gettempdir()) / f"cnctwin_bench_{os.getuid()}"
    fmu = out / f"Lag_{digest}" / "Lag.fmu"
    if fmu.is_file():
        return fmu
    cc = shutil.which("gcc") or shutil.which("cc")
    if cc is None:
        raise CncTwinError("the C-FMU benchmark fixture needs a C compiler (gcc or cc on PATH); none was found")
    stage = Path(tempfile.mkdtemp(prefix="cnctwin_lag_"))
    try:
        binaries = stage / "binaries" / "linux64"
        binaries.mkdir(parents=True)
        shutil.copy(SOURCE_DIR / "modelDescription.xml", stage / "modelDescription.xml")
        cmd = [cc, "-std=c99", "-O2", "-Wall", "-Werror", "-shared", "-fPIC", f"-I{FMI_HEADERS}",
               "-o", str(binaries / "Lag.so"), str(SOURCE_DIR / "lag.c"), "-lm"]
        done = subprocess.run(cmd, capture_output=True, text=True)
        if done.returncode != 0:
            raise CncTwinError(f"{SOURCE_DIR / 'lag.c'}: compilation failed: {done.stderr.strip()}")
        fmu.parent.mkdir(parents=True, exist_ok=True)
        tmp = fmu.with_suffix(f".{os.getpid()}.tmp")
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
            for f in sorted(stage.rglob("*")):
                if f.is_file():
                    zf.write(f, f.relative_to(stage).as_posix())
        os.replace(tmp, fmu)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
    return fmu


def lag_ring(fmu: str | Path | None = None, tau: float = 0.01, k_last: float = 1.0, fail_time: float = -1.0,
             fail_at: str = "c") -> System:
    """Four Lag FMU instances in a ring, as a :class:`~orchestrator.system.System` of FMUComponents.

    Parameters
    ----------
    fmu : str or Path, optional
        ``Lag.fmu`` (built by :func:`build_lag_fmu` when omitted).
    tau : float
        Time constant of every stage, s.
    k_last : float
        Gain of stage ``d`` (the others have gain 1); ``|k_last| <= 1`` keeps the ring stable;
        with 1 it settles to a non-zero level (no denormals to slow the timing).
    fail_time : float
        If >= 0, stage ``fail_at`` fails (fmi2Error) in the step that passes this time, s.
    fail_at : str
        Which stage gets ``fail_time``.

    Returns
    -------
    System
        Stage ``a`` starts at ``y = 1``, the others at 0; execution order a, b, c, d.
    """
    from ..fmu import FMUComponent

    fmu = fmu or build_lag_fmu()
    system = System("lag_ring")
    for name in RING:
        params: dict[str, object] = {"tau": tau, "k": k_last if name == "d" else 1.0, "y0": 1.0 if name == "a" else 0.0}
        if name == fail_at and fail_time >= 0.0:
            params["fail_time"] = fail_time
        system.add(FMUComponent(fmu, name, parameters=params))
    for src, dst in zip(RING, RING[1:] + RING[:1]):
        system.connect(f"{src}.y", f"{dst}.u")
    system.set_execution_order(RING)
    return system
