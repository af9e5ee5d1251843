/*
 * fmi2_wrapper.c -- variant A: FMI 2.0 co-simulation interface to the rotor core.
 *
 * Thin layer: value references are resolved through the generated table
 * fmu_variables.h (one scalar per correction node, SI units); all physics is in
 * ../core.  Every error path logs a message through the importer's logger and returns
 * fmi2Error.  No global mutable state: everything lives in the Instance.
 */
#include <ctype.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmu_common.h"
#include "fmu_variables.h"

typedef enum { MODE_INSTANTIATED, MODE_INIT, MODE_STEP, MODE_TERMINATED, MODE_ERROR } Mode;

typedef struct {
    RotorCore *core;
    fmi2CallbackFunctions cb;
    char name[128];
    int logging;
    Mode mode;
    double start_time;
} Instance;

typedef struct {
    CoreDynamic dyn;
    Mode mode;
    double start_time;
} Snapshot;

static void log_core(void *env, int level, const char *message)
{
    Instance *inst = (Instance *)env;
    fmi2Status status = level >= 2 ? fmi2Error : (level == 1 ? fmi2Warning : fmi2OK);
    if (!inst->cb.logger) return;
    if (level == 0 && !inst->logging) return;
    inst->cb.logger(inst->cb.componentEnvironment, inst->name, status,
                    level >= 2 ? "logStatusError" : "logAll", "%s", message);
}

static fmi2Status fail(Instance *inst, const char *fmt, const char *arg)
{
    char buf[512];
    snprintf(buf, sizeof buf, fmt, arg ? arg : "");
    log_core(inst, 2, buf);
    return fmi2Error;
}

/* "file:///a/b%20c/resources" -> "/a/b c/resources" */
static int uri_to_path(const char *uri, char *out, size_t n)
{
    size_t j = 0;
    const char *s = uri;
    if (strncmp(s, "file://", 7) == 0) s += 7;
    else if (strncmp(s, "file:", 5) == 0) s += 5;
    if (strncmp(s, "localhost/", 10) == 0) s += 9;
    for (; *s && j + 1 < n; s++) {
        if (*s == '%' && isxdigit((unsigned char)s[1]) && isxdigit((unsigned char)s[2])) {
            char hex[3] = {s[1], s[2], 0};
            out[j++] = (char)strtol(hex, NULL, 16);
            s += 2;
        } else {
            out[j++] = *s;
        }
    }
    out[j] = 0;
    return *s == 0 ? 0 : -1;
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    Instance *inst = (Instance *)c;
    (void)nCategories; (void)categories;
    if (!inst) return fmi2Error;
    inst->logging = loggingOn ? 1 : 0;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn)
{
    Instance *inst;
    char path[4096];
    (void)visible;
    if (!functions) return NULL;
    inst = (Instance *)calloc(1, sizeof(Instance));
    if (!inst) return NULL;
    inst->cb = *functions;
    snprintf(inst->name, sizeof inst->name, "%s", instanceName ? instanceName : "rotor");
    inst->logging = loggingOn ? 1 : 0;
    if (fmuType != fmi2CoSimulation) {
        fail(inst, "this FMU supports co-simulation only%s", NULL);
        free(inst);
        return NULL;
    }
    if (!fmuGUID || strcmp(fmuGUID, FMU_INSTANTIATION_TOKEN) != 0) {
        fail(inst, "GUID mismatch: got '%s', the binary was built for " FMU_INSTANTIATION_TOKEN,
             fmuGUID ? fmuGUID : "(null)");
        free(inst);
        return NULL;
    }
    if (!fmuResourceLocation || uri_to_path(fmuResourceLocation, path, sizeof path) != 0) {
        fail(inst, "invalid resource location '%s'", fmuResourceLocation ? fmuResourceLocation : "");
        free(inst);
        return NULL;
    }
    inst->core = core_create(path, log_core, inst);
    if (!inst->core || fmu_check_table(inst->core, FMU_VARS, FMU_N_VARS) != 0 ||
        fmu_apply_starts(inst->core, FMU_VARS, FMU_N_VARS) != 0) {
        fail(inst, "instantiation failed (see the messages above)%s", NULL);
        core_free(inst->core);
        free(inst);
        return NULL;
    }
    inst->mode = MODE_INSTANTIATED;
    return inst;
}

void fmi2FreeInstance(fmi2Component c)
{
    Instance *inst = (Instance *)c;
    if (!inst) return;
    core_free(inst->core);
    free(inst);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    Instance *inst = (Instance *)c;
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    if (!inst) return fmi2Error;
    if (inst->mode != MODE_INSTANTIATED)
        return fail(inst, "fmi2SetupExperiment is only allowed after instantiation%s", NULL);
    inst->start_time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    Instance *inst = (Instance *)c;
    if (!inst) return fmi2Error;
    if (inst->mode != MODE_INSTANTIATED)
        return fail(inst, "fmi2EnterInitializationMode: wrong state%s", NULL);
    inst->mode = MODE_INIT;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    Instance *inst = (Instance *)c;
    if (!inst) return fmi2Error;
    if (inst->mode != MODE_INIT)
        return fail(inst, "fmi2ExitInitializationMode: not in initialization mode%s", NULL);
    if (core_initialize(inst->core, inst->start_time) != 0) {
        inst->mode = MODE_ERROR;
        return fail(inst, "initialization failed (see the messages above)%s", NULL);
    }
    inst->mode = MODE_STEP;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    Instance *inst = (Instance *)c;
    if (!inst) return fmi2Error;
    inst->mode = MODE_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c)
{
    Instance *inst = (Instance *)c;
    if (!inst) return fmi2Error;
    memset(&inst->core->dyn, 0, sizeof inst->core->dyn);
    if (fmu_apply_starts(inst->core, FMU_VARS, FMU_N_VARS) != 0)
        return fail(inst, "reset failed%s", NULL);
    inst->mode = MODE_INSTANTIATED;
    inst->start_time = 0.0;
    return fmi2OK;
}

/* Look a variable up and check its FMI type. */
static const FmuVar *lookup(Instance *inst, fmi2ValueReference vr, int type)
{
    const FmuVar *v = fmu_find(FMU_VARS, FMU_N_VARS, vr);
    char buf[64];
    if (!v) {
        snprintf(buf, sizeof buf, "%u", vr);
        fail(inst, "unknown value reference %s", buf);
        return NULL;
    }
    if (v->type != type) {
        fail(inst, "variable '%s' has another type than the one requested", v->name);
        return NULL;
    }
    return v;
}

static fmi2Status get_values(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                             int type, double *out)
{
    Instance *inst = (Instance *)c;
    size_t i;
    if (!inst) return fmi2Error;
    if (nvr > 0 && (!vr || !out)) return fail(inst, "null value array%s", NULL);
    for (i = 0; i < nvr; i++) {
        const FmuVar *v = lookup(inst, vr[i], type);
        if (!v || fmu_get(inst->core, v, 0, &out[i]) != 0) return fmi2Error;
    }
    return fmi2OK;
}

static fmi2Status set_value(Instance *inst, fmi2ValueReference vr, int type, double value)
{
    const FmuVar *v = lookup(inst, vr, type);
    if (!v) return fmi2Error;
    if (v->kind == FK_OUTPUT || v->kind == FK_INDEPENDENT)
        return fail(inst, "variable '%s' is an output and cannot be set", v->name);
    if (v->kind == FK_FIXED && inst->mode != MODE_INSTANTIATED && inst->mode != MODE_INIT)
        return fail(inst, "fixed parameter '%s' can only be set before initialization ends",
                    v->name);
    if (inst->mode == MODE_TERMINATED || inst->mode == MODE_ERROR)
        return fail(inst, "cannot set '%s': the instance is terminated or in error", v->name);
    if (fmu_set(inst->core, v, 0, value) != 0) return fmi2Error;
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    return get_values(c, vr, nvr, FT_REAL, value);
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Integer value[])
{
    size_t i;
    fmi2Status s = fmi2OK;
    for (i = 0; i < nvr && s == fmi2OK; i++) {
        double x;
        s = get_values(c, &vr[i], 1, FT_INTEGER, &x);
        value[i] = (fmi2Integer)x;
    }
    return s;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Boolean value[])
{
    size_t i;
    fmi2Status s = fmi2OK;
    for (i = 0; i < nvr && s == fmi2OK; i++) {
        double x;
        s = get_values(c, &vr[i], 1, FT_BOOLEAN, &x);
        value[i] = x != 0.0 ? fmi2True : fmi2False;
    }
    return s;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         fmi2String value[])
{
    (void)vr; (void)value;
    if (!c) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    return fail((Instance *)c, "this FMU has no String variables%s", NULL);
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[])
{
    size_t i;
    if (!c) return fmi2Error;
    for (i = 0; i < nvr; i++)
        if (set_value((Instance *)c, vr[i], FT_REAL, value[i]) != fmi2OK) return fmi2Error;
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[])
{
    size_t i;
    if (!c) return fmi2Error;
    for (i = 0; i < nvr; i++)
        if (set_value((Instance *)c, vr[i], FT_INTEGER, (double)value[i]) != fmi2OK) return fmi2Error;
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean value[])
{
    size_t i;
    if (!c) return fmi2Error;
    for (i = 0; i < nvr; i++)
        if (set_value((Instance *)c, vr[i], FT_BOOLEAN, value[i] ? 1.0 : 0.0) != fmi2OK)
            return fmi2Error;
    return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[])
{
    (void)vr; (void)value;
    if (!c) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    return fail((Instance *)c, "this FMU has no String variables%s", NULL);
}

/* ---- FMU state: a plain copy of the core's dynamic part ---------------------- */
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    Instance *inst = (Instance *)c;
    Snapshot *s;
    if (!inst || !state) return fmi2Error;
    s = (Snapshot *)(*state ? *state : malloc(sizeof(Snapshot)));
    if (!s) return fail(inst, "out of memory saving the FMU state%s", NULL);
    s->dyn = inst->core->dyn;
    s->mode = inst->mode;
    s->start_time = inst->start_time;
    *state = s;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    Instance *inst = (Instance *)c;
    const Snapshot *s = (const Snapshot *)state;
    if (!inst) return fmi2Error;
    if (!s) return fail(inst, "fmi2SetFMUstate: null state%s", NULL);
    inst->core->dyn = s->dyn;
    inst->mode = s->mode;
    inst->start_time = s->start_time;
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    (void)c;
    if (state) {
        free(*state);
        *state = NULL;
    }
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size)
{
    (void)c; (void)state;
    *size = sizeof(Snapshot);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size)
{
    Instance *inst = (Instance *)c;
    if (!inst || !state) return fmi2Error;
    if (size < sizeof(Snapshot)) return fail(inst, "serialization buffer too small%s", NULL);
    memcpy(bytes, state, sizeof(Snapshot));
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size,
                                   fmi2FMUstate *state)
{
    Instance *inst = (Instance *)c;
    Snapshot *s;
    if (!inst || !state) return fmi2Error;
    if (size != sizeof(Snapshot))
        return fail(inst, "serialized state has the wrong size (another build?)%s", NULL);
    s = (Snapshot *)malloc(sizeof(Snapshot));
    if (!s) return fail(inst, "out of memory restoring the FMU state%s", NULL);
    memcpy(s, bytes, sizeof(Snapshot));
    *state = s;
    return fmi2OK;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[],
                                        size_t nUnknown, const fmi2ValueReference vKnown_ref[],
                                        size_t nKnown, const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    if (!c) return fmi2Error;
    return fail((Instance *)c, "directional derivatives are not provided%s", NULL);
}

/* ---- co-simulation ------------------------------------------------------------ */
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    (void)vr; (void)nvr; (void)order; (void)value;
    if (!c) return fmi2Error;
    return fail((Instance *)c, "input derivatives are not supported%s", NULL);
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    (void)vr; (void)nvr; (void)order; (void)value;
    if (!c) return fmi2Error;
    return fail((Instance *)c, "output derivatives are not supported%s", NULL);
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    Instance *inst = (Instance *)c;
    (void)currentCommunicationPoint; (void)noSetFMUStatePriorToCurrentPoint;
    if (!inst) return fmi2Error;
    if (inst->mode != MODE_STEP)
        return fail(inst, "fmi2DoStep: the instance is not initialized (or in error)%s", NULL);
    if (core_do_step(inst->core, communicationStepSize) != 0) {
        inst->mode = MODE_ERROR;
        return fail(inst, "step failed (see the messages above)%s", NULL);
    }
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    if (!c) return fmi2Error;
    return fail((Instance *)c, "fmi2CancelStep: steps are synchronous%s", NULL);
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    (void)s; (void)value;
    if (!c) return fmi2Error;
    return fail((Instance *)c, "fmi2GetStatus: steps are synchronous%s", NULL);
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    Instance *inst = (Instance *)c;
    if (!inst) return fmi2Error;
    if (s == fmi2LastSuccessfulTime) {
        *value = inst->core->dyn.time;
        return fmi2OK;
    }
    return fail(inst, "fmi2GetRealStatus: unsupported status kind%s", NULL);
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    (void)s; (void)value;
    if (!c) return fmi2Error;
    return fail((Instance *)c, "fmi2GetIntegerStatus: unsupported%s", NULL);
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    (void)s; (void)value;
    if (!c) return fmi2Error;
    return fail((Instance *)c, "fmi2GetBooleanStatus: unsupported%s", NULL);
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    (void)s; (void)value;
    if (!c) return fmi2Error;
    return fail((Instance *)c, "fmi2GetStringStatus: unsupported%s", NULL);
}
