"""A compiled stepping loop over FMI 2.0 and FMI 3.0 co-simulation FMUs (:class:`FastFMULoop`).

The Python :class:`~orchestrator.master.Master` pays some 10 µs of
interpreter work per FMI call (ctypes marshalling, numpy views, the wire
loop). :class:`FastFMULoop` resolves the connections once into arrays of
value references, slot indices and unit factors, and then runs N
communication steps entirely in C: a small loop compiled at first use with
the system C compiler (``gcc``/``cc``) and called through :mod:`ctypes`. The
C loop calls ``fmi2SetReal`` / ``fmi2DoStep`` / ``fmi2GetReal`` (FMI 3.0:
``fmi3SetFloat64`` / ``fmi3DoStep`` / ``fmi3GetFloat64``) through the
function pointers of the FMUs' loaded shared libraries, checks every status
and records chosen outputs into a preallocated array. One system may mix
FMI 2.0 and FMI 3.0 FMUs.

Semantics are those of the Python master over :class:`FMUComponent`, call for
call and operation for operation, so recordings are bit-identical:

* each communication step ``h`` is split into ``lcm(rates)`` ticks; a
  component of rate ``r`` steps every ``lcm/r``-th tick with ``h / r``, at
  ``t0 + (k·n + j)·(h / n)`` (integer tick count, no time accumulation);
* Gauss–Seidel (default): a component's inputs are taken from its sources'
  *current* outputs just before it steps; Jacobi: from the outputs at the
  start of the tick;
* before ``fmi2DoStep`` *all* Real inputs of a component are set in one
  ``fmi2SetReal`` (unconnected ones keep the value they had when the run
  started), after it *all* Real outputs are read in one ``fmi2GetReal``
  (FMI 3.0: the Float64 ones, ``fmi3SetFloat64`` / ``fmi3GetFloat64``, and
  ``fmi3DoStep`` with ``noSetFMUStatePriorToCurrentPoint = true``);
* an output value in our units is ``raw × from_fmu`` (``(raw − fmu offset) ×
  from_fmu`` for a role variable mapped to an affine unit, ``degC`` for our
  ``K``); an input receives ``(source × connection factor + connection
  offset) × to_fmu`` (``+ fmu offset``), each offset applied only when it is
  not 0 (units such as ``degC`` → ``K``), as :class:`FMUComponent` and the
  master's Python loop do.

Only Real variables can be connected (of an FMI 3.0 FMU: ``Float64``
variables, array elements included: an element is a port of its own, a
(value reference, position) pair resolved once, and each array is set or read
with its value reference once and ``nValues`` = its element count, as
:class:`FMUComponent` does). Recorded outputs and stop signals of an FMI 2.0 FMU may also be
Boolean or Integer (read with ``fmi2GetBoolean`` / ``fmi2GetInteger`` after
every step of their component). The other outputs of an :class:`FMUComponent`
(FMI 2.0: Integer, Boolean, String; FMI 3.0: all but ``Float64``) are read
after every step, one getter call per type as :class:`FMUComponent` does,
into its own buffers (String values copied, as the FMU's pointers are valid
only until its next call). After a run a component still initialised reads
them once more; one that failed gets those of its last good step, as on the
Python loop. Unconnected inputs of those types keep the values set at
initialisation. A run can end early:
after the first step at which every stop signal is non-zero, or at a check
step at which a checked output is not finite or outside its bounds (what
:meth:`orchestrator.master.Master.run` needs to stop where its Python loop
would, :mod:`orchestrator.fmu.master_loop`). A status worse than
``fmi2Warning`` (``fmi3Warning``) ends the loop, and so does an
``fmi3DoStep`` that returns ``earlyReturn`` or ``terminateSimulation``
(:func:`~orchestrator.fmu.fmi3.step_problem`; the C loop writes the
component's own :class:`~orchestrator.fmu.fmi3.StepFlags`). :class:`FMUError`
then names the component, the FMI function and the time, with the message
and clean-up of :class:`FMUComponent`, and :attr:`FastFMULoop.partial` holds
the steps completed before it.
"""
from __future__ import annotations

import ctypes
import hashlib
import math
import os
import shutil
import subprocess
import tempfile
import weakref
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np
from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave

from . import arrays, fmi3
from .component import FMUComponent, _Block
from .errors import FMUError, status_name

if TYPE_CHECKING:
    from ..system import System

#: FMI functions the loop calls, by the code the C loop reports in a failure.
FUNCTIONS = ("fmi2SetReal", "fmi2DoStep", "fmi2GetReal", "fmi2GetBoolean", "fmi2GetInteger")
#: The same for an FMI 3.0 FMU (code 3: the getter of one of its other output blocks, named by the block).
FUNCTIONS3 = ("fmi3SetFloat64", "fmi3DoStep", "fmi3GetFloat64")

_C_SOURCE = r"""
#include <math.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

typedef void *fmi2Component;
typedef int fmi2Status;
typedef unsigned int fmi2ValueReference;
typedef fmi2Status (*SetRealF)(fmi2Component, const fmi2ValueReference *, size_t, const double *);
typedef fmi2Status (*GetRealF)(fmi2Component, const fmi2ValueReference *, size_t, double *);
typedef fmi2Status (*DoStepF)(fmi2Component, double, double, int);
typedef fmi2Status (*GetIntF)(fmi2Component, const fmi2ValueReference *, size_t, int *);
/* FMI 3.0 (fmi3Status has the same values as fmi2Status; fmi3Boolean is bool) */
typedef fmi2Status (*SetFloat64F)(void *, const fmi2ValueReference *, size_t, const double *, size_t);
typedef fmi2Status (*GetFloat64F)(void *, const fmi2ValueReference *, size_t, double *, size_t);
typedef fmi2Status (*DoStep3F)(void *, double, double, bool, bool *, bool *, bool *, double *);
/* any fmi3GetXXX but Binary: the value array is only passed on, so its element type does not matter */
typedef fmi2Status (*Get3F)(void *, const fmi2ValueReference *, size_t, void *, size_t);
/* fmi2GetInteger, fmi2GetBoolean, fmi2GetString (the same) */
typedef fmi2Status (*Get2F)(void *, const fmi2ValueReference *, size_t, void *);

typedef struct {
    int n_comp;
    void **comp;
    void **set_real;
    void **get_real;
    void **do_step;
    const int *in_start;          /* inputs of component c: in_start[c] .. in_start[c+1]-1 */
    const unsigned int *in_vr;
    const int *in_src;            /* source slot, or -1: constant in_const */
    const double *in_factor;      /* connection unit factor */
    const double *in_offset;      /* connection unit offset (added after the factor when not 0) */
    const double *in_to;          /* our unit -> FMU unit */
    const double *in_const;
    const int *out_start;         /* outputs of component c: out_start[c] .. out_start[c+1]-1 */
    const unsigned int *out_vr;
    const double *out_from;       /* FMU unit -> our unit */
    double *slots;                /* current outputs, our units, one per output (same index) */
    double *snapshot;             /* Jacobi: slots at the start of the tick */
    double *buffer;               /* scratch, >= the largest in/out count */
    int n_fine;
    const int *tick_start;        /* tick j: tick_start[j] .. tick_start[j+1]-1 into tick_comp, tick_h */
    const int *tick_comp;
    const double *tick_h;
    int jacobi;
    int n_rec;
    const int *rec_slot;
    double *rec;                  /* (n_steps + 1) x n_rec, row 0 written by the caller */
    int err[4];                   /* component, function (0 set, 1 step, 2 get, 3 getBoolean, 4 getInteger;
                                     FMI 3.0: 3 the getter of other block err_block), tick,
                                     status (-1: fmi3DoStep set earlyReturn or terminateSimulation) */
    long err_step;
    /* discrete outputs read after each step (recorded or stop signals): slots n_real + i */
    int n_real;
    void **get_boolean;
    void **get_integer;
    const int *bool_start;        /* Boolean outputs of component c: bool_start[c] .. bool_start[c+1]-1 */
    const unsigned int *bool_vr;
    const int *int_start;         /* Integer outputs, slots after all Booleans */
    const unsigned int *int_vr;
    int *ibuffer;
    double *in_last;              /* value (our units) each input received at its last step, -1 sources too */
    int n_stop;                   /* stop when every stop slot is non-zero after a step */
    const int *stop_slot;
    int n_check;                  /* every check_every-th step: a check slot not finite or outside [lo, hi] */
    int check_every;
    const int *check_slot;
    const double *check_lo;
    const double *check_hi;
    long k_end;                   /* steps done when cnct_run returned 2 (stop) or 3 (check) */
    const int *fmi3;              /* component c is an FMI 3.0 FMU: set/get/do_step are fmi3SetFloat64,
                                     fmi3GetFloat64, fmi3DoStep */
    void **step_flags;            /* FMI 3.0 component c: step_flags[4c .. 4c+3] -> eventHandlingNeeded,
                                     terminateSimulation, earlyReturn (bool), lastSuccessfulTime (double) */
    /* an FMUComponent's other outputs (FMI 2.0: Integer, Boolean, String; FMI 3.0: all but Float64), read after
       every step into its own buffers, one getter call per block, as FMUComponent does; so a failed instance
       keeps the values of its last good step */
    const int *other_start;       /* blocks of component c: other_start[c] .. other_start[c+1]-1 */
    void **other_get;
    void **other_vr;              /* const fmi2ValueReference * */
    const int *other_n;
    void **other_buf;
    int err_block;
    const int *other_kind;        /* bit 0: FMI 3.0 getter (nValues after the array); bit 1: String block, the
                                     strings (valid until the FMU's next call) copied into other_text */
    void **other_text;            /* String block i: char *[other_n[i]], grown with realloc (cnct_free_text) */
    void **other_cap;             /* String block i: size_t[other_n[i]], bytes allocated for each copy */
    const double *in_shift;       /* FMU value at our 0 of input i (a role mapping into an affine unit), or 0 */
    const double *out_shift;      /* the same for output i: our value = (raw - out_shift) * out_from */
    /* the value references of each call: an FMI 3.0 array's once for all its elements (nValues > nvr) */
    const int *in_vr_start;       /* value references of component c's inputs: in_vr[in_vr_start[c] ..] */
    const int *out_vr_start;      /* the same for its outputs in out_vr */
    const int *other_nvr;         /* value references of other block i (other_n[i]: its values) */
} Loop;

static int copy_texts(char **text, size_t *cap, const char *const *src, size_t n) {
    for (size_t k = 0; k < n; ++k) {
        const char *s = src[k] ? src[k] : "";
        const size_t len = strlen(s) + 1;
        if (len > cap[k]) {
            char *grown = (char *)realloc(text[k], len);
            if (!grown) return 1;
            text[k] = grown;
            cap[k] = len;
        }
        memcpy(text[k], s, len);
    }
    return 0;
}

void cnct_free_text(char **text, size_t *cap, size_t n) {
    for (size_t k = 0; k < n; ++k) { free(text[k]); text[k] = NULL; cap[k] = 0; }
}

static fmi2Status set_real(Loop *L, int c, size_t n) {
    const fmi2ValueReference *vr = L->in_vr + L->in_vr_start[c];
    const size_t nvr = (size_t)(L->in_vr_start[c + 1] - L->in_vr_start[c]);
    if (L->fmi3[c]) return ((SetFloat64F)L->set_real[c])(L->comp[c], vr, nvr, L->buffer, n);
    return ((SetRealF)L->set_real[c])(L->comp[c], vr, n, L->buffer);
}

static int get_outputs(Loop *L, int c) {
    int a = L->out_start[c], b = L->out_start[c + 1];
    if (b == a) return 0;
    const size_t n = (size_t)(b - a);
    const fmi2ValueReference *vr = L->out_vr + L->out_vr_start[c];
    const size_t nvr = (size_t)(L->out_vr_start[c + 1] - L->out_vr_start[c]);
    fmi2Status s = L->fmi3[c] ? ((GetFloat64F)L->get_real[c])(L->comp[c], vr, nvr, L->buffer, n)
                              : ((GetRealF)L->get_real[c])(L->comp[c], vr, n, L->buffer);
    if (s > 1) { L->err[1] = 2; L->err[3] = s; return 1; }
    for (int i = a; i < b; ++i) {
        const double raw = L->buffer[i - a];
        L->slots[i] = (L->out_shift[i] != 0.0 ? raw - L->out_shift[i] : raw) * L->out_from[i];
    }
    return 0;
}

static int get_discrete(Loop *L, int c) {
    for (int i = L->other_start[c]; i < L->other_start[c + 1]; ++i) {
        const size_t n = (size_t)L->other_n[i];
        const fmi2ValueReference *vr = (const fmi2ValueReference *)L->other_vr[i];
        const int kind = L->other_kind[i];
        fmi2Status s = (kind & 1) ? ((Get3F)L->other_get[i])(L->comp[c], vr, (size_t)L->other_nvr[i],
                                                             L->other_buf[i], n)
                                  : ((Get2F)L->other_get[i])(L->comp[c], vr, n, L->other_buf[i]);
        if (s > 1) { L->err[1] = 3; L->err[3] = s; L->err_block = i; return 1; }
        if ((kind & 2) && copy_texts((char **)L->other_text[i], (size_t *)L->other_cap[i],
                                     (const char *const *)L->other_buf[i], n)) {
            L->err[1] = 3; L->err[3] = -2; L->err_block = i; return 1;   /* out of memory */
        }
    }
    int a = L->bool_start[c], b = L->bool_start[c + 1];
    const int n_bool = L->bool_start[L->n_comp];
    if (b > a) {
        fmi2Status s = ((GetIntF)L->get_boolean[c])(L->comp[c], L->bool_vr + a, (size_t)(b - a), L->ibuffer);
        if (s > 1) { L->err[1] = 3; L->err[3] = s; return 1; }
        for (int i = a; i < b; ++i) L->slots[L->n_real + i] = L->ibuffer[i - a] ? 1.0 : 0.0;
    }
    a = L->int_start[c]; b = L->int_start[c + 1];
    if (b > a) {
        fmi2Status s = ((GetIntF)L->get_integer[c])(L->comp[c], L->int_vr + a, (size_t)(b - a), L->ibuffer);
        if (s > 1) { L->err[1] = 4; L->err[3] = s; return 1; }
        for (int i = a; i < b; ++i) L->slots[L->n_real + n_bool + i] = (double)L->ibuffer[i - a];
    }
    return 0;
}

int cnct_pull(Loop *L) {
    for (int c = 0; c < L->n_comp; ++c) {
        if (get_outputs(L, c) || get_discrete(L, c)) { L->err[0] = c; L->err[2] = -1; L->err_step = 0; return 1; }
    }
    return 0;
}

int cnct_run(Loop *L, long k0, long n_steps, double t0, double h) {
    const double dt = h / L->n_fine;
    for (long k = k0; k < k0 + n_steps; ++k) {
        for (int j = 0; j < L->n_fine; ++j) {
            const double t = t0 + (double)(k * L->n_fine + j) * dt;
            const double *src = L->slots;
            if (L->jacobi) {
                memcpy(L->snapshot, L->slots, sizeof(double) * (size_t)L->out_start[L->n_comp]);
                src = L->snapshot;
            }
            for (int e = L->tick_start[j]; e < L->tick_start[j + 1]; ++e) {
                int c = L->tick_comp[e];
                int a = L->in_start[c], b = L->in_start[c + 1];
                fmi2Status s;
                if (b > a) {
                    for (int i = a; i < b; ++i) {
                        double v = L->in_const[i];
                        if (L->in_src[i] >= 0) {
                            v = src[L->in_src[i]] * L->in_factor[i];
                            if (L->in_offset[i] != 0.0) v += L->in_offset[i];
                        }
                        L->in_last[i] = v;
                        L->buffer[i - a] = v * L->in_to[i];
                        if (L->in_shift[i] != 0.0) L->buffer[i - a] += L->in_shift[i];
                    }
                    s = set_real(L, c, (size_t)(b - a));
                    if (s > 1) {
                        L->err[0] = c; L->err[1] = 0; L->err[2] = j; L->err[3] = s; L->err_step = k;
                        return 1;
                    }
                }
                int flagged = 0;
                if (L->fmi3[c]) {
                    /* as FMUComponent: terminateSimulation and earlyReturn cleared, the other two kept */
                    void **f = L->step_flags + 4 * (size_t)c;
                    *(bool *)f[1] = false;
                    *(bool *)f[2] = false;
                    s = ((DoStep3F)L->do_step[c])(L->comp[c], t, L->tick_h[e], true, (bool *)f[0], (bool *)f[1],
                                                  (bool *)f[2], (double *)f[3]);
                    flagged = s <= 1 && (*(bool *)f[2] || *(bool *)f[1]);
                } else {
                    s = ((DoStepF)L->do_step[c])(L->comp[c], t, L->tick_h[e], 1);
                }
                if (s > 1 || flagged) {
                    L->err[0] = c; L->err[1] = 1; L->err[2] = j; L->err[3] = flagged ? -1 : s; L->err_step = k;
                    return 1;
                }
                if (get_outputs(L, c) || get_discrete(L, c)) {
                    L->err[0] = c; L->err[2] = j; L->err_step = k; return 1;
                }
            }
        }
        double *row = L->rec + (size_t)(k - k0 + 1) * (size_t)L->n_rec;
        for (int r = 0; r < L->n_rec; ++r) row[r] = L->slots[L->rec_slot[r]];
        const long done = k + 1;
        if (L->n_check > 0 && done % L->check_every == 0) {
            for (int r = 0; r < L->n_check; ++r) {
                const double v = L->slots[L->check_slot[r]];
                if (!isfinite(v) || v < L->check_lo[r] || v > L->check_hi[r]) { L->k_end = done; return 3; }
            }
        }
        if (L->n_stop > 0) {
            int all = 1;
            for (int r = 0; r < L->n_stop; ++r) {
                if (L->slots[L->stop_slot[r]] == 0.0) { all = 0; break; }
            }
            if (all) { L->k_end = done; return 2; }
        }
    }
    return 0;
}
"""


class _Loop(ctypes.Structure):
    _fields_ = [
        ("n_comp", ctypes.c_int),
        ("comp", ctypes.POINTER(ctypes.c_void_p)),
        ("set_real", ctypes.POINTER(ctypes.c_void_p)),
        ("get_real", ctypes.POINTER(ctypes.c_void_p)),
        ("do_step", ctypes.POINTER(ctypes.c_void_p)),
        ("in_start", ctypes.POINTER(ctypes.c_int)),
        ("in_vr", ctypes.POINTER(ctypes.c_uint)),
        ("in_src", ctypes.POINTER(ctypes.c_int)),
        ("in_factor", ctypes.POINTER(ctypes.c_double)),
        ("in_offset", ctypes.POINTER(ctypes.c_double)),
        ("in_to", ctypes.POINTER(ctypes.c_double)),
        ("in_const", ctypes.POINTER(ctypes.c_double)),
        ("out_start", ctypes.POINTER(ctypes.c_int)),
        ("out_vr", ctypes.POINTER(ctypes.c_uint)),
        ("out_from", ctypes.POINTER(ctypes.c_double)),
        ("slots", ctypes.POINTER(ctypes.c_double)),
        ("snapshot", ctypes.POINTER(ctypes.c_double)),
        ("buffer", ctypes.POINTER(ctypes.c_double)),
        ("n_fine", ctypes.c_int),
        ("tick_start", ctypes.POINTER(ctypes.c_int)),
        ("tick_comp", ctypes.POINTER(ctypes.c_int)),
        ("tick_h", ctypes.POINTER(ctypes.c_double)),
        ("jacobi", ctypes.c_int),
        ("n_rec", ctypes.c_int),
        ("rec_slot", ctypes.POINTER(ctypes.c_int)),
        ("rec", ctypes.POINTER(ctypes.c_double)),
        ("err", ctypes.c_int * 4),
        ("err_step", ctypes.c_long),
        ("n_real", ctypes.c_int),
        ("get_boolean", ctypes.POINTER(ctypes.c_void_p)),
        ("get_integer", ctypes.POINTER(ctypes.c_void_p)),
        ("bool_start", ctypes.POINTER(ctypes.c_int)),
        ("bool_vr", ctypes.POINTER(ctypes.c_uint)),
        ("int_start", ctypes.POINTER(ctypes.c_int)),
        ("int_vr", ctypes.POINTER(ctypes.c_uint)),
        ("ibuffer", ctypes.POINTER(ctypes.c_int)),
        ("in_last", ctypes.POINTER(ctypes.c_double)),
        ("n_stop", ctypes.c_int),
        ("stop_slot", ctypes.POINTER(ctypes.c_int)),
        ("n_check", ctypes.c_int),
        ("check_every", ctypes.c_int),
        ("check_slot", ctypes.POINTER(ctypes.c_int)),
        ("check_lo", ctypes.POINTER(ctypes.c_double)),
        ("check_hi", ctypes.POINTER(ctypes.c_double)),
        ("k_end", ctypes.c_long),
        ("fmi3", ctypes.POINTER(ctypes.c_int)),
        ("step_flags", ctypes.POINTER(ctypes.c_void_p)),
        ("other_start", ctypes.POINTER(ctypes.c_int)),
        ("other_get", ctypes.POINTER(ctypes.c_void_p)),
        ("other_vr", ctypes.POINTER(ctypes.c_void_p)),
        ("other_n", ctypes.POINTER(ctypes.c_int)),
        ("other_buf", ctypes.POINTER(ctypes.c_void_p)),
        ("err_block", ctypes.c_int),
        ("other_kind", ctypes.POINTER(ctypes.c_int)),
        ("other_text", ctypes.POINTER(ctypes.c_void_p)),
        ("other_cap", ctypes.POINTER(ctypes.c_void_p)),
        ("in_shift", ctypes.POINTER(ctypes.c_double)),
        ("out_shift", ctypes.POINTER(ctypes.c_double)),
        ("in_vr_start", ctypes.POINTER(ctypes.c_int)),
        ("out_vr_start", ctypes.POINTER(ctypes.c_int)),
        ("other_nvr", ctypes.POINTER(ctypes.c_int)),
    ]


_LIBRARY: ctypes.CDLL | None = None


def compiler() -> str | None:
    """Path of the system C compiler (``$CC``, ``gcc`` or ``cc``), None when there is none."""
    cc = os.environ.get("CC")
    if cc and shutil.which(cc):
        return shutil.which(cc)
    return shutil.which("gcc") or shutil.which("cc")


def _library() -> ctypes.CDLL:
    """Compile (once per source version, cached in the temp folder) and load the C loop."""
    global _LIBRARY
    if _LIBRARY is not None:
        return _LIBRARY
    cc = compiler()
    if cc is None:
        raise FMUError("FastFMULoop needs a C compiler (gcc or cc on PATH, or $CC); none was found")
    digest = hashlib.sha1(_C_SOURCE.encode()).hexdigest()[:12]
    folder = Path(tempfile.gettempdir()) / f"cnctwin_fast_loop_{os.getuid() if hasattr(os, 'getuid') else 0}"
    folder.mkdir(parents=True, exist_ok=True)
    lib = folder / f"fast_loop_{digest}.so"
    if not lib.is_file():
        src = folder / f"fast_loop_{digest}.c"
        src.write_text(_C_SOURCE, encoding="utf-8")
        tmp = folder / f"fast_loop_{digest}.{os.getpid()}.so"
        cmd = [cc, "-std=c99", "-O2", "-Wall", "-shared", "-fPIC", "-o", str(tmp), str(src)]
        done = subprocess.run(cmd, capture_output=True, text=True)
        if done.returncode != 0:
            raise FMUError(f"FastFMULoop: compiling {src} failed ({' '.join(cmd)}): {done.stderr.strip()}")
        os.replace(tmp, lib)
    dll = ctypes.CDLL(str(lib))
    dll.cnct_run.argtypes = [ctypes.POINTER(_Loop), ctypes.c_long, ctypes.c_long, ctypes.c_double, ctypes.c_double]
    dll.cnct_run.restype = ctypes.c_int
    dll.cnct_pull.argtypes = [ctypes.POINTER(_Loop)]
    dll.cnct_pull.restype = ctypes.c_int
    dll.cnct_free_text.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t]
    dll.cnct_free_text.restype = None
    _LIBRARY = dll
    return dll


# ----------------------------------------------------------------------------- instances
@dataclass
class _Port:
    """One Real variable of an instance: value reference, factor and offset to its units from ours."""

    vr: int
    to_fmu: float
    offset: float = 0.0  # FMU value = to_fmu × ours + offset
    element: int = -1  # an FMI 3.0 array's element: its row-major position; -1 for a scalar
    count: int = 1  # values behind ``vr`` (the array's element count)


def _value_references(ports: Sequence[_Port]) -> list[int]:
    """The value references of one get/set call over ``ports`` (an array's once, at its first element).

    The ports hold every element of each array, in row-major order (as :class:`FMUComponent` binds them).
    """
    return [p.vr for p in ports if p.element <= 0]


class _Instance:
    """An FMU instance as the loop sees it: slave, component pointer, Real ports by name.

    The ports are the Real variables of an FMI 2.0 FMU and the ``Float64`` ones of an
    FMI 3.0 FMU (:attr:`v3`); every other input and output is in :attr:`discrete`.
    """

    def __init__(self, name: str, obj: FMU2Slave | FMU3Slave | FMUComponent) -> None:
        self.name = name
        self.owner: FMUComponent | None = obj if isinstance(obj, FMUComponent) else None
        #: FMI 3.0: the output flags of fmi3DoStep, written by the C loop (an FMUComponent's own).
        self.flags: fmi3.StepFlags | None = None
        #: FMUComponent: its output blocks other than Real (FMI 2.0) or Float64 (FMI 3.0), read by the C loop
        #: after every step into their own buffers, String values copied into :attr:`texts` (a failed instance
        #: gets them in :meth:`FastFMULoop._write_back`).
        self.other_blocks: list[_Block] = []
        #: String block -> (char *[n], size_t[n]): the C loop's copies of its strings (freed with the instance).
        self.texts: dict[int, tuple[ctypes.Array, ctypes.Array]] = {}
        #: input alias -> the input it names (FMUComponent.canonical): one port, set once per step
        self.input_alias: dict[str, str] = {}
        if self.owner is not None:
            self.v3 = fmi3.is_fmi3(self.owner.fmi_version)
            self.slave: FMU2Slave | FMU3Slave = obj._slave  # noqa: SLF001 - same package; the instance it drives
            self.flags = obj._step_flags  # noqa: SLF001
            real_getter = "fmi3GetFloat64" if self.v3 else "fmi2GetReal"
            self.inputs: dict[str, _Port] = {}
            self.outputs: dict[str, _Port] = {}
            self.discrete: set[str] = set()
            self.input_alias = dict(obj._input_alias)  # noqa: SLF001
            for b in obj._bindings:  # noqa: SLF001
                if b.ours.name in self.input_alias:
                    continue
                if b.native.getter != real_getter:
                    self.discrete.add(b.ours.name)
                    continue
                port = _Port(int(b.theirs.valueReference), float(b.to_fmu), float(b.offset), b.element, b.count)
                if b.ours.causality == "input":
                    self.inputs[b.ours.name] = port
                elif b.ours.causality == "output":
                    self.outputs[b.ours.name] = port
            self.other_blocks = [block for block in obj._out_blocks  # noqa: SLF001
                                 if block.native.getter != real_getter]
            for block in self.other_blocks:
                if block.native.ours == "String":
                    self.texts[id(block)] = ((ctypes.c_void_p * block.n)(), (ctypes.c_size_t * block.n)())
            if self.texts:
                weakref.finalize(self, _free_texts, _library(), list(self.texts.values()))
            self.discrete_outputs: dict[str, tuple[int, str]] = {} if self.v3 else {
                b.ours.name: (int(b.theirs.valueReference), b.ours.type)
                for b in obj._bindings  # noqa: SLF001
                if b.ours.causality == "output" and b.ours.type in ("Boolean", "Integer")}
        elif isinstance(obj, (FMU2Slave, FMU3Slave)):
            self.v3 = isinstance(obj, FMU3Slave)
            self.slave = obj
            self.flags = fmi3.StepFlags() if self.v3 else None
            md = read_model_description(obj.unzipDirectory, validate=False)
            real = "Float64" if self.v3 else "Real"
            self.inputs, self.outputs, self.discrete = {}, {}, set()
            self.discrete_outputs = {}
            for v in md.modelVariables:
                if v.causality not in ("input", "output"):
                    continue
                shape = tuple(getattr(v, "shape", None) or ()) if arrays.is_array(v) else ()
                names = arrays.element_names(v.name, shape) if shape else [v.name]
                if v.causality == "input" and getattr(v, "alias", None) is not None:
                    for name, head in zip(names, arrays.element_names(v.alias.name, shape) if shape
                                          else [v.alias.name]):
                        self.input_alias[name] = head  # an FMI 3.0 <Alias>: the input it names
                    continue
                if v.type != real:
                    self.discrete.update(names)
                    if (not self.v3 and v.causality == "output"
                            and v.type in ("Boolean", "Integer", "Enumeration")):
                        kind = "Boolean" if v.type == "Boolean" else "Integer"
                        self.discrete_outputs[v.name] = (int(v.valueReference), kind)
                    continue
                ports = self.inputs if v.causality == "input" else self.outputs
                for k, name in enumerate(names):
                    ports[name] = _Port(int(v.valueReference), 1.0, 0.0, k if shape else -1, len(names))
        else:
            raise FMUError(f"FastFMULoop: {name!r} is a {type(obj).__name__}; expected an fmpy FMU2Slave or "
                           f"FMU3Slave, or an FMUComponent")
        if not self.slave.component:
            function = "fmi3InstantiateCoSimulation" if self.v3 else "fmi2Instantiate"
            raise FMUError(f"FastFMULoop: {name!r} is not instantiated ({function} first)", component=name)

    @property
    def functions(self) -> tuple[str, ...]:
        """The FMI functions of the loop's failure codes (:data:`FUNCTIONS` or :data:`FUNCTIONS3`)."""
        return FUNCTIONS3 if self.v3 else FUNCTIONS

    def pointers(self) -> tuple[int, ...]:
        """(component, set Real, get Real, do step, fmi2GetBoolean, fmi2GetInteger) as addresses.

        FMI 3.0: ``fmi3SetFloat64``, ``fmi3GetFloat64``, ``fmi3DoStep``, and 0 for the
        two discrete getters (its other outputs are read through :meth:`other_pointers`).
        """
        dll = self.slave.dll
        comp = self.slave.component
        comp = comp.value if isinstance(comp, ctypes.c_void_p) else int(comp)
        names = (("fmi3SetFloat64", "fmi3GetFloat64", "fmi3DoStep") if self.v3
                 else ("fmi2SetReal", "fmi2GetReal", "fmi2DoStep", "fmi2GetBoolean", "fmi2GetInteger"))
        addresses = [ctypes.cast(getattr(dll, f), ctypes.c_void_p).value for f in names]
        return (comp, *addresses, *([0, 0] if self.v3 else []))

    def other_pointers(self) -> list[tuple[int, int, int, int, int, int, int, int]]:
        """(getter, value references, count, buffer, kind, copies, capacities, value reference count) of
        :attr:`other_blocks` (the count is of values: an FMI 3.0 array's elements are one value reference).

        ``kind``: bit 0 an FMI 3.0 getter, bit 1 a String block (copies and capacities: its :attr:`texts`,
        else 0).
        """
        out = []
        for b in self.other_blocks:
            text, cap = self.texts.get(id(b), (None, None))
            out.append((ctypes.cast(getattr(self.slave.dll, b.native.getter), ctypes.c_void_p).value,
                        ctypes.addressof(b.vr), b.n, ctypes.addressof(b.buffer),
                        int(self.v3) | (2 if text is not None else 0),
                        ctypes.addressof(text) if text is not None else 0,
                        ctypes.addressof(cap) if cap is not None else 0, b.nvr))
        return out

    def held_strings(self, block: _Block) -> None:
        """Put the C loop's copies of String ``block``'s values (those of the last read) into the component."""
        text, _ = self.texts[id(block)]
        for i, name in enumerate(block.names):
            block.values[name] = (ctypes.string_at(text[i]) if text[i] else b"").decode("utf-8")

    def flag_pointers(self) -> list[int]:
        """Addresses of the four fmi3DoStep output flags (FMI 3.0), else four zeros."""
        f = self.flags
        if f is None:
            return [0, 0, 0, 0]
        return [ctypes.addressof(x) for x in (f.event_handling_needed, f.terminate_simulation, f.early_return,
                                              f.last_successful_time)]

    def get_real(self, port: _Port) -> float:
        """One Real (FMI 3.0: Float64) value straight from the FMU, in its units (fmpy checks the status);
        of an array element, the whole array is read and the element taken."""
        raw = (ctypes.c_double * port.count)()
        vrs = (ctypes.c_uint * 1)(port.vr)
        if self.v3:
            self.slave.fmi3GetFloat64(self.slave.component, vrs, 1, raw, port.count)
        else:
            self.slave.fmi2GetReal(self.slave.component, vrs, 1, raw)
        return raw[max(port.element, 0)]

    def port(self, variable: str, causality: str) -> _Port:
        ports = self.inputs if causality == "input" else self.outputs
        if variable in ports:
            return ports[variable]
        real = "Float64" if self.v3 else "Real"
        if variable in self.discrete:
            what = "an FMI 3.0 FMU's variable other than Float64" if self.v3 else "not a Real variable"
            raise FMUError(f"FastFMULoop: {self.name}.{variable} is {what}; the compiled loop connects and records "
                           f"{real} variables only", component=self.name)
        raise FMUError(f"FastFMULoop: {self.name} has no {real} {causality} {variable!r}; it has {sorted(ports)}",
                       component=self.name)


@dataclass
class FastLoopResult:
    """What :meth:`FastFMULoop.run` returns.

    Attributes
    ----------
    t : ndarray, shape (N + 1,)
        Communication instants ``t0 + k h``, s.
    values : ndarray, shape (N + 1, R)
        Recorded outputs (our units), row ``k`` at ``t[k]``.
    names : list of str
        ``"component.variable"`` of each column.
    event : {"end", "stop", "check", "error"}
        Why the run returned: all steps done, the stop signals were all true
        (after the last row), a checked output was not finite or outside its
        bounds at a check step (the last row), or an FMI call failed (the rows
        of the steps completed before it; see :attr:`FastFMULoop.partial`).
    """

    t: np.ndarray
    values: np.ndarray
    names: list[str]
    event: str = "end"

    def __getitem__(self, name: str) -> np.ndarray:
        """Column of ``"component.variable"``."""
        try:
            return self.values[:, self.names.index(name)]
        except ValueError:
            raise KeyError(f"{name!r} was not recorded; recorded: {self.names}") from None


def _split(reference: str) -> tuple[str, str]:
    if "." not in reference:
        raise FMUError(f"FastFMULoop: {reference!r}: expected 'component.variable'")
    comp, var = reference.split(".", 1)
    return comp, var


class FastFMULoop:
    """Step several FMU instances N communication steps in compiled code.

    Parameters
    ----------
    instances : Mapping[str, FMU2Slave | FMU3Slave | FMUComponent]
        The instances by name, in the default execution (Gauss–Seidel) order,
        FMI 2.0 and FMI 3.0 alike. fmpy ``FMU2Slave`` / ``FMU3Slave`` objects
        must be instantiated (FMI 3.0: with ``earlyReturnAllowed = false``) and
        initialised by the caller; :class:`FMUComponent` objects are set up by :meth:`run` when
        still in state ``"instantiated"`` (along the execution order, with
        their connected inputs first, as the master does).
    connections : sequence of (str, str) or Connection
        ``("source.output", "target.input")`` pairs, or
        :class:`~orchestrator.system.Connection` objects (their unit factor
        and offset are applied).
    record : sequence of str
        ``"component.output"`` to record every communication step.
    order : sequence of str, optional
        Execution order (a permutation of the names).
    rates : Mapping[str, int], optional
        Steps per communication step (default 1 each).
    method : {"gauss-seidel", "jacobi"}
        Coupling scheme.
    stop : sequence of str, optional
        ``"component.output"`` (Real, Boolean or Integer): :meth:`run` returns
        early, with ``event = "stop"``, after the first step at which all of
        them are non-zero.
    checks : Mapping[str, (float, float)], optional
        ``{"component.output": (low, high)}`` (Real): after every
        ``check_every``-th step (counted from the first run), :meth:`run`
        returns early, with ``event = "check"``, when one of them is not
        finite or outside its bounds (``(-inf, inf)``: finite only).
    check_every : int
        Period of those checks, communication steps (>= 1 when ``checks``).

    Record and stop references may name Boolean or Integer outputs of FMI 2.0
    FMUs too (read with ``fmi2GetBoolean`` / ``fmi2GetInteger`` after every step
    of their component, recorded as 0.0/1.0 or the integer as a float). Of an
    FMI 3.0 FMU, only ``Float64`` variables can be connected, recorded, stop
    signals or checked.

    Raises
    ------
    FMUError
        Unknown names, non-Real (FMI 3.0: non-Float64) connected or recorded variables, an input
        connected twice, no C compiler.

    Examples
    --------
    >>> loop = FastFMULoop({"a": a, "b": b}, [("a.y", "b.u"), ("b.y", "a.u")], record=["b.y"])  # doctest: +SKIP
    >>> result = loop.run(1000, 1e-3)                                                            # doctest: +SKIP
    """

    def __init__(
        self,
        instances: Mapping[str, FMU2Slave | FMU3Slave | FMUComponent],
        connections: Sequence[tuple[str, str] | object] = (),
        record: Sequence[str] = (),
        order: Sequence[str] | None = None,
        rates: Mapping[str, int] | None = None,
        method: str = "gauss-seidel",
        stop: Sequence[str] = (),
        checks: Mapping[str, tuple[float, float]] | None = None,
        check_every: int = 0,
    ) -> None:
        if not instances:
            raise FMUError("FastFMULoop: no instances given")
        if method not in ("gauss-seidel", "jacobi"):
            raise FMUError(f"FastFMULoop: method must be 'gauss-seidel' or 'jacobi', got {method!r}")
        self.objects = dict(instances)
        self.order = list(order) if order is not None else list(self.objects)
        if sorted(self.order) != sorted(self.objects):
            raise FMUError(f"FastFMULoop: order {self.order} must name every instance once: {sorted(self.objects)}")
        self.rates = {n: int((rates or {}).get(n, 1)) for n in self.order}
        bad = [n for n, r in self.rates.items() if r < 1]
        if bad:
            raise FMUError(f"FastFMULoop: rates must be positive integers, got {dict((n, self.rates[n]) for n in bad)}")
        self.method = method
        self.units = [_Instance(n, self.objects[n]) for n in self.order]
        self._index = {u.name: i for i, u in enumerate(self.units)}
        self.connections: list[tuple[str, str, float, float]] = []  # (source, target, factor, offset)
        seen: dict[str, str] = {}
        for c in connections:
            if isinstance(c, tuple):
                source, target, factor, offset = c[0], c[1], 1.0, 0.0
            else:
                source, target = c.source, c.target
                factor, offset = float(getattr(c, "factor", 1.0)), float(getattr(c, "offset", 0.0))
            comp, var = _split(target)
            target = f"{comp}.{self._unit(target).input_alias.get(var, var)}"  # an alias: the input it names
            if target in seen:
                raise FMUError(f"FastFMULoop: {target} is connected twice ({seen[target]} and {source})")
            seen[target] = source
            self._unit(source).port(_split(source)[1], "output")
            self._unit(target).port(_split(target)[1], "input")
            self.connections.append((source, target, factor, offset))
        self.record = list(record)
        self.stop = list(stop)
        self.checks = {ref: (float(lo), float(hi)) for ref, (lo, hi) in (checks or {}).items()}
        if self.checks and (int(check_every) != check_every or check_every < 1):
            raise FMUError(f"FastFMULoop: check_every must be a positive integer with checks, got {check_every!r}")
        self.check_every = int(check_every)
        self._discrete: list[tuple[int, str, int, str]] = []  # (unit index, variable, vr, Boolean | Integer)
        for ref in self.record + self.stop:
            self._output(ref, discrete_ok=True)
        for ref in self.checks:
            self._output(ref, discrete_ok=False)
        self._library = _library()
        self._k = 0
        #: Result of the steps completed before an FMI call failed in the last :meth:`run` (else None).
        self.partial: FastLoopResult | None = None
        self._failed_block = None  # the output block whose getter failed in the last run

    @classmethod
    def from_system(cls, system: System, record: Sequence[str] = (), method: str = "gauss-seidel",
                    stop: Sequence[str] = (), checks: Mapping[str, tuple[float, float]] | None = None,
                    check_every: int = 0) -> FastFMULoop:
        """The loop of a :class:`~orchestrator.system.System` whose components are all FMUComponents.

        Execution order, rates and connections (with their unit factors) are the system's;
        the other arguments are those of the constructor.
        """
        instances: Mapping = system.components
        return cls(instances, system.connections, record, order=system.execution_order(), rates=system.rates,
                   method=method, stop=stop, checks=checks, check_every=check_every)

    def _output(self, reference: str, discrete_ok: bool) -> None:
        """Check that ``reference`` is a Real (or, with ``discrete_ok``, Boolean/Integer) output; note discrete ones."""
        u = self._unit(reference)
        var = _split(reference)[1]
        if var in u.outputs:
            return
        if discrete_ok and var in u.discrete_outputs:
            vr, kind = u.discrete_outputs[var]
            entry = (self._index[u.name], var, vr, kind)
            if entry not in self._discrete:
                self._discrete.append(entry)
            return
        u.port(var, "output")  # raises, naming what there is

    def _unit(self, reference: str) -> _Instance:
        comp, _ = _split(reference)
        try:
            return self.units[self._index[comp]]
        except KeyError:
            raise FMUError(f"FastFMULoop: {reference}: no instance {comp!r}; it has {sorted(self._index)}") from None

    # ------------------------------------------------------------------ set-up
    def _initialize(self, t0: float) -> None:
        """Set up FMUComponents still in state 'instantiated', along the order, inputs first (as the master)."""
        for u in self.units:
            owner = u.owner
            if owner is None or owner.state != "instantiated":
                continue
            for source, target, factor, offset in self.connections:
                if _split(target)[0] != u.name:
                    continue
                src = self._unit(source)
                value = (src.owner.values[_split(source)[1]] if src.owner is not None else None)
                if value is None:
                    value = np.array([src.get_real(src.outputs[_split(source)[1]])])
                dst = owner.values[_split(target)[1]]
                if factor == 1.0:
                    np.copyto(dst, value, casting="unsafe")
                else:
                    np.multiply(value, factor, out=dst, casting="unsafe")
                if offset != 0.0:
                    np.add(dst, offset, out=dst, casting="unsafe")
            owner.setup(t0)
        for u in self.units:
            if u.owner is not None and u.owner.state != "initialized":
                raise FMUError(f"FastFMULoop: {u.name} is in state {u.owner.state!r}; expected 'initialized'",
                               component=u.name)

    def _build(self, h: float, n_steps: int) -> tuple[_Loop, list[object]]:
        keep: list[object] = []  # ctypes/numpy buffers that must outlive the call

        def arr(values: Sequence, ctype: type) -> ctypes.Array:
            a = (ctype * max(1, len(values)))(*values)
            keep.append(a)
            return a

        slot_of: dict[str, int] = {}
        out_start, out_vr, out_from, out_shift, out_vr_start = [0], [], [], [], [0]
        n_real = 0
        for u in self.units:
            for name, port in u.outputs.items():
                slot_of[f"{u.name}.{name}"] = n_real
                n_real += 1
                out_from.append(1.0 / port.to_fmu)
                out_shift.append(port.offset)
            out_start.append(n_real)
            out_vr += _value_references(list(u.outputs.values()))
            out_vr_start.append(len(out_vr))
        bool_start, bool_vr, int_start, int_vr = [0], [], [0], []
        bool_names, int_names = [], []
        for i, u in enumerate(self.units):
            for c, var, vr, kind in self._discrete:
                if c == i:
                    (bool_vr if kind == "Boolean" else int_vr).append(vr)
                    (bool_names if kind == "Boolean" else int_names).append(f"{u.name}.{var}")
            bool_start.append(len(bool_vr))
            int_start.append(len(int_vr))
        for i, ref in enumerate(bool_names + int_names):
            slot_of[ref] = n_real + i
        source_of = {target: (source, factor, offset) for source, target, factor, offset in self.connections}
        in_start, in_vr, in_src, in_factor, in_offset, in_to, in_const = [0], [], [], [], [], [], []
        in_shift, in_vr_start, n_in = [], [0], 0
        for u in self.units:
            in_vr += _value_references(list(u.inputs.values()))
            in_vr_start.append(len(in_vr))
            for name, port in u.inputs.items():
                ref = f"{u.name}.{name}"
                n_in += 1
                in_to.append(port.to_fmu)
                in_shift.append(port.offset)
                if ref in source_of:
                    source, factor, offset = source_of[ref]
                    in_src.append(slot_of[source])
                    in_factor.append(factor)
                    in_offset.append(offset)
                    in_const.append(0.0)
                else:
                    in_src.append(-1)
                    in_factor.append(1.0)
                    in_offset.append(0.0)
                    in_const.append(self._held_input(u, name, port))
            in_start.append(n_in)
        n_fine = math.lcm(*self.rates.values())
        tick_start, tick_comp, tick_h = [0], [], []
        for j in range(n_fine):
            for i, u in enumerate(self.units):
                if j % (n_fine // self.rates[u.name]) == 0:
                    tick_comp.append(i)
                    tick_h.append(h / self.rates[u.name])
            tick_start.append(len(tick_comp))
        ptrs = [u.pointers() for u in self.units]
        counts = [b - a for a, b in zip(out_start, out_start[1:])] + [b - a for a, b in zip(in_start, in_start[1:])]
        width = max([1] + counts)
        discrete_counts = ([b - a for a, b in zip(bool_start, bool_start[1:])]
                           + [b - a for a, b in zip(int_start, int_start[1:])])
        self._slots = np.zeros(max(1, n_real + len(bool_vr) + len(int_vr)))
        self._rec = np.zeros((n_steps + 1, len(self.record)))
        self._in_refs = [(u, name) for u in self.units for name in u.inputs]
        self._in_last = np.array([float(u.owner.values[name][0]) if u.owner is not None else c
                                  for (u, name), c in zip(self._in_refs, in_const)] or [0.0])
        self._in_connected = [src >= 0 for src in in_src]
        keep += [self._slots, self._rec, self._in_last]
        checks = list(self.checks.items())
        others, other_start = [], [0]
        for u in self.units:
            others += u.other_pointers()
            other_start.append(len(others))
        self._other_blocks = [(u, b) for u in self.units for b in u.other_blocks]
        dptr = ctypes.POINTER(ctypes.c_double)
        loop = _Loop(
            n_comp=len(self.units),
            comp=arr([p[0] for p in ptrs], ctypes.c_void_p),
            set_real=arr([p[1] for p in ptrs], ctypes.c_void_p),
            get_real=arr([p[2] for p in ptrs], ctypes.c_void_p),
            do_step=arr([p[3] for p in ptrs], ctypes.c_void_p),
            in_start=arr(in_start, ctypes.c_int), in_vr=arr(in_vr, ctypes.c_uint), in_src=arr(in_src, ctypes.c_int),
            in_factor=arr(in_factor, ctypes.c_double), in_offset=arr(in_offset, ctypes.c_double),
            in_to=arr(in_to, ctypes.c_double),
            in_const=arr(in_const, ctypes.c_double),
            out_start=arr(out_start, ctypes.c_int), out_vr=arr(out_vr, ctypes.c_uint),
            out_from=arr(out_from, ctypes.c_double),
            slots=self._slots.ctypes.data_as(dptr),
            snapshot=arr([0.0] * n_real, ctypes.c_double),
            buffer=arr([0.0] * width, ctypes.c_double),
            n_fine=n_fine,
            tick_start=arr(tick_start, ctypes.c_int), tick_comp=arr(tick_comp, ctypes.c_int),
            tick_h=arr(tick_h, ctypes.c_double),
            jacobi=int(self.method == "jacobi"),
            n_rec=len(self.record),
            rec_slot=arr([slot_of[r] for r in self.record], ctypes.c_int),
            rec=self._rec.ctypes.data_as(dptr),
            n_real=n_real,
            get_boolean=arr([p[4] for p in ptrs], ctypes.c_void_p),
            get_integer=arr([p[5] for p in ptrs], ctypes.c_void_p),
            bool_start=arr(bool_start, ctypes.c_int), bool_vr=arr(bool_vr, ctypes.c_uint),
            int_start=arr(int_start, ctypes.c_int), int_vr=arr(int_vr, ctypes.c_uint),
            ibuffer=arr([0] * max([1] + discrete_counts), ctypes.c_int),
            in_last=self._in_last.ctypes.data_as(dptr),
            n_stop=len(self.stop),
            stop_slot=arr([slot_of[r] for r in self.stop], ctypes.c_int),
            n_check=len(checks),
            check_every=max(1, self.check_every),
            check_slot=arr([slot_of[r] for r, _ in checks], ctypes.c_int),
            check_lo=arr([lo for _, (lo, _) in checks], ctypes.c_double),
            check_hi=arr([hi for _, (_, hi) in checks], ctypes.c_double),
            k_end=0,
            fmi3=arr([int(u.v3) for u in self.units], ctypes.c_int),
            step_flags=arr([a for u in self.units for a in u.flag_pointers()], ctypes.c_void_p),
            other_start=arr(other_start, ctypes.c_int),
            other_get=arr([o[0] for o in others], ctypes.c_void_p),
            other_vr=arr([o[1] for o in others], ctypes.c_void_p),
            other_n=arr([o[2] for o in others], ctypes.c_int),
            other_buf=arr([o[3] for o in others], ctypes.c_void_p),
            err_block=-1,
            other_kind=arr([o[4] for o in others], ctypes.c_int),
            other_text=arr([o[5] for o in others], ctypes.c_void_p),
            other_cap=arr([o[6] for o in others], ctypes.c_void_p),
            in_shift=arr(in_shift, ctypes.c_double),
            out_shift=arr(out_shift, ctypes.c_double),
            in_vr_start=arr(in_vr_start, ctypes.c_int),
            out_vr_start=arr(out_vr_start, ctypes.c_int),
            other_nvr=arr([o[7] for o in others], ctypes.c_int),
        )
        self._slot_of = slot_of
        return loop, keep

    @staticmethod
    def _held_input(u: _Instance, name: str, port: _Port) -> float:
        """Value (our units) an unconnected input keeps over the run."""
        if u.owner is not None:
            return float(u.owner.values[name][0])
        return (u.get_real(port) - port.offset) / port.to_fmu

    # ------------------------------------------------------------------ run
    def run(self, n_steps: int, h: float, t0: float = 0.0) -> FastLoopResult:
        """Run ``n_steps`` communication steps of length ``h`` from ``t0`` (continuing where the last run ended).

        Parameters
        ----------
        n_steps : int
            Communication steps, >= 0.
        h : float
            Communication step, s, > 0.
        t0 : float
            Start time of the experiment, s; step ``k`` starts at ``t0 + k h``
            where ``k`` counts the steps of all runs of this loop.

        Returns
        -------
        FastLoopResult
            Recorded outputs at ``t0 + k h`` for the steps of this run (row 0: before the first);
            fewer than ``n_steps`` when a stop signal or a check ended the run (``event``).

        Raises
        ------
        FMUError
            A status worse than ``fmi2Warning`` / ``fmi3Warning``, or an ``fmi3DoStep`` returning
            ``earlyReturn`` or ``terminateSimulation``, naming component, function and time;
            :attr:`partial` then holds the rows of the steps completed before it.
        """
        if int(n_steps) != n_steps or n_steps < 0:
            raise FMUError(f"FastFMULoop: n_steps must be a non-negative integer, got {n_steps!r}")
        if not (h > 0.0 and math.isfinite(h)):
            raise FMUError(f"FastFMULoop: step must be positive and finite, got {h!r}")
        n_steps = int(n_steps)
        self.partial = None
        self._failed_block = None
        if self._k == 0:
            self._initialize(t0)
        loop, keep = self._build(h, n_steps)
        if self._library.cnct_pull(ctypes.byref(loop)) != 0:
            raise self._error(loop, t0, h)
        self._rec[0] = [self._slots[self._slot_of[r]] for r in self.record]
        k0 = self._k
        status = self._library.cnct_run(ctypes.byref(loop), k0, n_steps, float(t0), float(h))
        event = {0: "end", 1: "error", 2: "stop", 3: "check"}[status]
        k_end = {"end": k0 + n_steps, "error": int(loop.err_step)}.get(event, int(loop.k_end))
        t = t0 + np.arange(k0, k_end + 1) * h
        if event == "error":
            error = self._error(loop, t0, h)
            self.partial = FastLoopResult(t, self._rec[: k_end - k0 + 1], list(self.record), event)
            self._write_back(error.time if error.time is not None else t0 + k_end * h)
            del keep
            raise error
        self._k = k_end
        self._write_back(t0 + self._k * h)
        del keep
        return FastLoopResult(t, self._rec[: k_end - k0 + 1], list(self.record), event)

    def _write_back(self, t_end: float) -> None:
        """Hand the current values to the FMUComponents still initialised.

        Real outputs from the loop, each connected input the value it received
        at its component's last step, discrete outputs read once (those of a
        failed instance from the C loop's reads after its last good step).
        """
        for (u, name), connected, value in zip(self._in_refs, self._in_connected, self._in_last):
            if connected and u.owner is not None:
                u.owner.values[name][0] = value
        for u in self.units:
            if u.owner is None:
                continue
            for name in u.outputs:  # a failed instance keeps the outputs of its last good step
                u.owner.values[name][0] = self._slots[self._slot_of[f"{u.name}.{name}"]]
            if u.owner.state != "initialized":
                # a failed instance is freed: its other outputs from the buffers (String: the copies) of its
                # last reads, except a block whose getter failed (FMUComponent unpacks neither)
                for block in u.other_blocks:
                    if block is self._failed_block:
                        continue
                    if block.native.ours == "String":
                        u.held_strings(block)
                    else:
                        block.unpack()
                continue
            u.owner.time = t_end
            if u.discrete:
                u.owner._get_discrete_outputs()  # noqa: SLF001 - same package; status-checked there

    def _error(self, loop: _Loop, t0: float, h: float) -> FMUError:
        c, fn, j, status = (int(x) for x in loop.err)
        u = self.units[c]
        if fn == 3 and int(loop.err_block) >= 0:  # the getter of one of its other output blocks
            self._failed_block = self._other_blocks[int(loop.err_block)][1]
            function = self._failed_block.native.getter
            if status == -2:
                return FMUError(f"{u.name}: out of memory copying the values of {function} after a step "
                                "(FastFMULoop)", component=u.name, function=function)
        else:
            function = u.functions[fn]
        n_fine = math.lcm(*self.rates.values())
        t = t0 + (int(loop.err_step) * n_fine + max(j, 0)) * (h / n_fine)
        if fn >= 2 and j >= 0:  # reading outputs after the step: FMUComponent's time is the step's end
            t = t + h / self.rates[u.name]
        if status < 0:  # fmi3DoStep returned earlyReturn or terminateSimulation, in the flags u.flags
            what = fmi3.step_problem(u.flags, t, h / self.rates[u.name])
            if u.owner is not None:
                u.owner.time = t
                return u.owner._end(function, what, None)  # noqa: SLF001 - FMUComponent's message and clean-up
            return FMUError(f"{u.name}: {function} {what} at t = {t:.6f} s (FastFMULoop)", component=u.name,
                            function=function, time=t)
        if u.owner is not None:
            u.owner.time = t
            return u.owner._failure(function, status)  # noqa: SLF001 - same message and clean-up as FMUComponent
        name = fmi3.status_name(status) if u.v3 else status_name(status)
        return FMUError(f"{u.name}: {function} returned {name} at t = {t:.6f} s (FastFMULoop)",
                        component=u.name, function=function, time=t, status=status)


def _free_texts(library: ctypes.CDLL, texts: list[tuple[ctypes.Array, ctypes.Array]]) -> None:
    """Free the C loop's copies of an instance's String outputs (finaliser of :class:`_Instance`)."""
    for text, cap in texts:
        library.cnct_free_text(ctypes.addressof(text), ctypes.addressof(cap), len(text))
