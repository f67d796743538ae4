/*
 * Lag: a first-order lag written directly against the FMI 2.0 C API (co-simulation), one input and
 * one output: the cnctwin benchmark fixture for the cost of a master's communication step.
 *
 * Model: tau y' = k u - y, u held over the step; exact zero-order-hold solution
 *     y(t + h) = k u + (y(t) - k u) exp(-h / tau).
 *
 * Failure injection: if fail_time >= 0, fmi2DoStep returns fmi2Error (and logs why) for the first
 * step whose end time exceeds fail_time.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

enum { VR_TAU, VR_K, VR_Y0, VR_FAIL_TIME, VR_U, VR_Y, VR_COUNT };

typedef struct {
    double r[VR_COUNT];
    int initialized;
    char *name;
    fmi2CallbackFunctions cb;
} Lag;

static const double START[VR_COUNT] = {0.01, 1.0, 0.0, -1.0, 0.0, 0.0};

static void say(Lag *m, fmi2Status status, const char *category, const char *text) {
    if (m->cb.logger) m->cb.logger(m->cb.componentEnvironment, m->name, status, category, "%s", text);
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) {
    (void)c; (void)on; (void)n; (void)cat;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String resources,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)guid; (void)resources; (void)visible; (void)loggingOn;
    if (type != fmi2CoSimulation || !functions) return NULL;
    Lag *m = (Lag *)calloc(1, sizeof(Lag));
    if (!m) return NULL;
    m->name = (char *)malloc(strlen(name) + 1);
    strcpy(m->name, name);
    m->cb = *functions;
    memcpy(m->r, START, sizeof(START));
    return m;
}

void fmi2FreeInstance(fmi2Component c) {
    Lag *m = (Lag *)c;
    if (!m) return;
    free(m->name);
    free(m);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDef, fmi2Real tol, fmi2Real t0, fmi2Boolean stopDef,
                               fmi2Real stop) {
    (void)c; (void)tolDef; (void)tol; (void)t0; (void)stopDef; (void)stop;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Lag *m = (Lag *)c;
    if (!(m->r[VR_TAU] > 0.0)) {
        say(m, fmi2Error, "logStatusError", "tau must be > 0");
        return fmi2Error;
    }
    m->r[VR_Y] = m->r[VR_Y0];
    m->initialized = 1;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }

fmi2Status fmi2Reset(fmi2Component c) {
    Lag *m = (Lag *)c;
    memcpy(m->r, START, sizeof(START));
    m->initialized = 0;
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[]) {
    Lag *m = (Lag *)c;
    for (size_t i = 0; i < n; ++i) {
        if (vr[i] >= VR_COUNT) return fmi2Error;
        value[i] = m->r[vr[i]];
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real value[]) {
    Lag *m = (Lag *)c;
    for (size_t i = 0; i < n; ++i) {
        if (vr[i] >= VR_Y) return fmi2Error;
        if (m->initialized && vr[i] < VR_U) return fmi2Error; /* parameters are fixed */
        m->r[vr[i]] = value[i];
    }
    return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    Lag *m = (Lag *)c;
    (void)noSetPrior;
    if (!m->initialized) return fmi2Error;
    if (m->r[VR_FAIL_TIME] >= 0.0 && t + h > m->r[VR_FAIL_TIME] * (1.0 + 1e-12)) {
        say(m, fmi2Error, "logStatusError", "deliberate failure (fail_time reached)");
        return fmi2Error;
    }
    double target = m->r[VR_K] * m->r[VR_U];
    m->r[VR_Y] = target + (m->r[VR_Y] - target) * exp(-h / m->r[VR_TAU]);
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) {
    (void)c; (void)s; (void)n; return fmi2Error;
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) {
    (void)c; (void)s; (void)b; (void)n; return fmi2Error;
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) {
    (void)c; (void)b; (void)n; (void)s; return fmi2Error;
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real dv[], fmi2Real dz[]) {
    (void)c; (void)u; (void)nu; (void)z; (void)nz; (void)dv; (void)dz; return fmi2Error;
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)c; (void)vr; (void)n; (void)order; (void)value; return fmi2Error;
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)c; (void)vr; (void)n; (void)order; (void)value; return fmi2Error;
}

fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) {
    (void)c; (void)s; (void)v; return fmi2Error;
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) {
    (void)c; (void)s; (void)v; return fmi2Error;
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) {
    (void)c; (void)s; (void)v; return fmi2Error;
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) {
    (void)c; (void)s; (void)v; return fmi2Error;
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) {
    (void)c; (void)s; (void)v; return fmi2Error;
}
