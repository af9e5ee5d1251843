/*
 * fmi3_wrapper.c -- variant B: FMI 3.0 co-simulation interface to the rotor core.
 *
 * Thin layer: value references (array variables for the correction field, Boolean
 * switches, Int32 selectors, kW / kN m units, blade-down azimuth convention) are
 * resolved through the generated table fmu_variables.h; all physics is in ../core.
 * Every error path logs through logMessage and returns fmi3Error.  No global
 * mutable state.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "fmu_common.h"
#include "fmu_variables.h"

typedef enum { MODE_INSTANTIATED, MODE_INIT, MODE_STEP, MODE_TERMINATED, MODE_ERROR } Mode;

typedef struct {
    RotorCore *core;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
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
    fmi3Status status = level >= 2 ? fmi3Error : (level == 1 ? fmi3Warning : fmi3OK);
    if (!inst->log) return;
    if (level == 0 && !inst->logging) return;
    inst->log(inst->env, status, level >= 2 ? "logStatusError" : "logEvents", message);
}

static fmi3Status fail(Instance *inst, const char *fmt, const char *arg)
{
    char buf[512];
    snprintf(buf, sizeof buf, fmt, arg ? arg : "");
    log_core(inst, 2, buf);
    return fmi3Error;
}

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[])
{
    Instance *inst = (Instance *)instance;
    (void)nCategories; (void)categories;
    if (!inst) return fmi3Error;
    inst->logging = loggingOn ? 1 : 0;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible,
                                          fmi3Boolean loggingOn, fmi3InstanceEnvironment env,
                                          fmi3LogMessageCallback logMessage)
{
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    if (logMessage) logMessage(env, fmi3Error, "logStatusError",
                               "this FMU supports co-simulation only");
    return NULL;
}

fmi3Instance fmi3InstantiateScheduledExecution(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment env,
    fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
    fmi3LockPreemptionCallback lockPreemption, fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible;
    (void)loggingOn; (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (logMessage) logMessage(env, fmi3Error, "logStatusError",
                               "this FMU supports co-simulation only");
    return NULL;
}

fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
    fmi3Boolean earlyReturnAllowed, const fmi3ValueReference requiredIntermediateVariables[],
    size_t nRequiredIntermediateVariables, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3IntermediateUpdateCallback intermediateUpdate)
{
    Instance *inst;
    (void)visible; (void)eventModeUsed; (void)earlyReturnAllowed;
    (void)requiredIntermediateVariables; (void)nRequiredIntermediateVariables; (void)intermediateUpdate;
    inst = (Instance *)calloc(1, sizeof(Instance));
    if (!inst) return NULL;
    inst->env = instanceEnvironment;
    inst->log = logMessage;
    inst->logging = loggingOn ? 1 : 0;
    snprintf(inst->name, sizeof inst->name, "%s", instanceName ? instanceName : "rotor");
    if (!instantiationToken || strcmp(instantiationToken, FMU_INSTANTIATION_TOKEN) != 0) {
        fail(inst, "instantiation token mismatch: got '%s', the binary was built for "
             FMU_INSTANTIATION_TOKEN, instantiationToken ? instantiationToken : "(null)");
        free(inst);
        return NULL;
    }
    if (!resourcePath || !resourcePath[0]) {
        fail(inst, "no resource path given%s", NULL);
        free(inst);
        return NULL;
    }
    inst->core = core_create(resourcePath, log_core, inst);
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

void fmi3FreeInstance(fmi3Instance instance)
{
    Instance *inst = (Instance *)instance;
    if (!inst) return;
    core_free(inst->core);
    free(inst);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                       fmi3Float64 tolerance, fmi3Float64 startTime,
                                       fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    Instance *inst = (Instance *)instance;
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    if (!inst) return fmi3Error;
    if (inst->mode != MODE_INSTANTIATED)
        return fail(inst, "fmi3EnterInitializationMode: wrong state%s", NULL);
    inst->start_time = startTime;
    inst->mode = MODE_INIT;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    Instance *inst = (Instance *)instance;
    if (!inst) return fmi3Error;
    if (inst->mode != MODE_INIT)
        return fail(inst, "fmi3ExitInitializationMode: not in initialization mode%s", NULL);
    if (core_initialize(inst->core, inst->start_time) != 0) {
        inst->mode = MODE_ERROR;
        return fail(inst, "initialization failed (see the messages above)%s", NULL);
    }
    inst->mode = MODE_STEP;
    return fmi3OK;
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance)
{
    if (!instance) return fmi3Error;
    return fail((Instance *)instance, "event mode is not supported%s", NULL);
}

fmi3Status fmi3Terminate(fmi3Instance instance)
{
    Instance *inst = (Instance *)instance;
    if (!inst) return fmi3Error;
    inst->mode = MODE_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance)
{
    Instance *inst = (Instance *)instance;
    if (!inst) return fmi3Error;
    memset(&inst->core->dyn, 0, sizeof inst->core->dyn);
    if (fmu_apply_starts(inst->core, FMU_VARS, FMU_N_VARS) != 0)
        return fail(inst, "reset failed%s", NULL);
    inst->mode = MODE_INSTANTIATED;
    inst->start_time = 0.0;
    return fmi3OK;
}

/* ---- getters and setters ----------------------------------------------------- */
static const FmuVar *lookup(Instance *inst, fmi3ValueReference vr, int type)
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

/* Read all elements of the variables vr into out (nValues in total). */
static fmi3Status get_values(Instance *inst, const fmi3ValueReference vr[], size_t nvr, int type,
                             double *out, size_t nValues)
{
    size_t i, j = 0;
    int k;
    for (i = 0; i < nvr; i++) {
        const FmuVar *v = lookup(inst, vr[i], type);
        if (!v) return fmi3Error;
        for (k = 0; k < v->count; k++, j++) {
            if (j >= nValues) return fail(inst, "value array too short for '%s'", v->name);
            if (fmu_get(inst->core, v, k, &out[j]) != 0) return fmi3Error;
        }
    }
    if (j != nValues) return fail(inst, "nValues does not match the variables' sizes%s", NULL);
    return fmi3OK;
}

static fmi3Status set_values(Instance *inst, const fmi3ValueReference vr[], size_t nvr, int type,
                             const double *in, size_t nValues)
{
    size_t i, j = 0;
    int k;
    for (i = 0; i < nvr; i++) {
        const FmuVar *v = lookup(inst, vr[i], type);
        if (!v) return fmi3Error;
        if (v->kind == FK_OUTPUT || v->kind == FK_INDEPENDENT)
            return fail(inst, "variable '%s' is not settable", v->name);
        if (v->kind == FK_FIXED && inst->mode != MODE_INSTANTIATED && inst->mode != MODE_INIT)
            return fail(inst, "fixed parameter '%s' can only be set before initialization ends",
                        v->name);
        if (inst->mode == MODE_TERMINATED || inst->mode == MODE_ERROR)
            return fail(inst, "cannot set '%s': the instance is terminated or in error", v->name);
        for (k = 0; k < v->count; k++, j++) {
            if (j >= nValues) return fail(inst, "value array too short for '%s'", v->name);
            if (fmu_set(inst->core, v, k, in[j]) != 0) return fmi3Error;
        }
    }
    if (j != nValues) return fail(inst, "nValues does not match the variables' sizes%s", NULL);
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          fmi3Float64 values[], size_t nValues)
{
    if (!instance) return fmi3Error;
    return get_values((Instance *)instance, vr, nvr, FT_REAL, values, nValues);
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Float64 values[], size_t nValues)
{
    if (!instance) return fmi3Error;
    return set_values((Instance *)instance, vr, nvr, FT_REAL, values, nValues);
}

/* Int32 and Boolean go through a double buffer (few values; selectors and switches). */
#define SMALL_BUFFER 256
#define CONVERTING_ACCESSORS(Name, CType, FT, TO_C)                                             \
    fmi3Status fmi3Get##Name(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,   \
                             CType values[], size_t nValues)                                     \
    {                                                                                            \
        double buf[SMALL_BUFFER];                                                                \
        size_t i;                                                                                \
        fmi3Status s;                                                                            \
        if (!instance) return fmi3Error;                                                         \
        if (nValues > SMALL_BUFFER)                                                              \
            return fail((Instance *)instance, "too many values requested at once%s", NULL);      \
        s = get_values((Instance *)instance, vr, nvr, FT, buf, nValues);                         \
        for (i = 0; s == fmi3OK && i < nValues; i++) values[i] = TO_C(buf[i]);                   \
        return s;                                                                                \
    }                                                                                            \
    fmi3Status fmi3Set##Name(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,   \
                             const CType values[], size_t nValues)                               \
    {                                                                                            \
        double buf[SMALL_BUFFER];                                                                \
        size_t i;                                                                                \
        if (!instance) return fmi3Error;                                                         \
        if (nValues > SMALL_BUFFER)                                                              \
            return fail((Instance *)instance, "too many values set at once%s", NULL);            \
        for (i = 0; i < nValues; i++) buf[i] = (double)values[i];                                \
        return set_values((Instance *)instance, vr, nvr, FT, buf, nValues);                      \
    }

#define TO_INT32(x) ((fmi3Int32)(x))
#define TO_BOOL(x) ((x) != 0.0 ? fmi3True : fmi3False)
CONVERTING_ACCESSORS(Int32, fmi3Int32, FT_INTEGER, TO_INT32)
CONVERTING_ACCESSORS(Boolean, fmi3Boolean, FT_BOOLEAN, TO_BOOL)

/* Types this FMU does not use: any access is an error (an empty request is fine). */
#define UNUSED_ACCESSORS(Name, CType)                                                            \
    fmi3Status fmi3Get##Name(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,   \
                             CType values[], size_t nValues)                                     \
    {                                                                                            \
        (void)vr; (void)values; (void)nValues;                                                   \
        if (!instance) return fmi3Error;                                                         \
        if (nvr == 0) return fmi3OK;                                                             \
        return fail((Instance *)instance, "this FMU has no " #Name " variables%s", NULL);        \
    }                                                                                            \
    fmi3Status fmi3Set##Name(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,   \
                             const CType values[], size_t nValues)                               \
    {                                                                                            \
        (void)vr; (void)values; (void)nValues;                                                   \
        if (!instance) return fmi3Error;                                                         \
        if (nvr == 0) return fmi3OK;                                                             \
        return fail((Instance *)instance, "this FMU has no " #Name " variables%s", NULL);        \
    }

UNUSED_ACCESSORS(Float32, fmi3Float32)
UNUSED_ACCESSORS(Int8, fmi3Int8)
UNUSED_ACCESSORS(UInt8, fmi3UInt8)
UNUSED_ACCESSORS(Int16, fmi3Int16)
UNUSED_ACCESSORS(UInt16, fmi3UInt16)
UNUSED_ACCESSORS(UInt32, fmi3UInt32)
UNUSED_ACCESSORS(Int64, fmi3Int64)
UNUSED_ACCESSORS(UInt64, fmi3UInt64)
UNUSED_ACCESSORS(String, fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         size_t valueSizes[], fmi3Binary values[], size_t nValues)
{
    (void)vr; (void)valueSizes; (void)values; (void)nValues;
    if (!instance) return fmi3Error;
    if (nvr == 0) return fmi3OK;
    return fail((Instance *)instance, "this FMU has no Binary variables%s", NULL);
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues)
{
    (void)vr; (void)valueSizes; (void)values; (void)nValues;
    if (!instance) return fmi3Error;
    if (nvr == 0) return fmi3OK;
    return fail((Instance *)instance, "this FMU has no Binary variables%s", NULL);
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                        fmi3Clock values[])
{
    (void)vr; (void)values;
    if (!instance) return fmi3Error;
    if (nvr == 0) return fmi3OK;
    return fail((Instance *)instance, "this FMU has no clocks%s", NULL);
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                        const fmi3Clock values[])
{
    (void)vr; (void)values;
    if (!instance) return fmi3Error;
    if (nvr == 0) return fmi3OK;
    return fail((Instance *)instance, "this FMU has no clocks%s", NULL);
}

/* ---- dependencies, state, derivatives ------------------------------------------ */
fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference vr,
                                               size_t *nDependencies)
{
    (void)vr; (void)nDependencies;
    if (!instance) return fmi3Error;
    return fail((Instance *)instance, "variable dependencies are not provided%s", NULL);
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[],
                                       fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[], size_t nDependencies)
{
    (void)dependent; (void)elementIndicesOfDependent; (void)independents;
    (void)elementIndicesOfIndependents; (void)dependencyKinds; (void)nDependencies;
    if (!instance) return fmi3Error;
    return fail((Instance *)instance, "variable dependencies are not provided%s", NULL);
}

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *state)
{
    Instance *inst = (Instance *)instance;
    Snapshot *s;
    if (!inst || !state) return fmi3Error;
    s = (Snapshot *)(*state ? *state : malloc(sizeof(Snapshot)));
    if (!s) return fail(inst, "out of memory saving the FMU state%s", NULL);
    s->dyn = inst->core->dyn;
    s->mode = inst->mode;
    s->start_time = inst->start_time;
    *state = s;
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState state)
{
    Instance *inst = (Instance *)instance;
    const Snapshot *s = (const Snapshot *)state;
    if (!inst) return fmi3Error;
    if (!s) return fail(inst, "fmi3SetFMUState: null state%s", NULL);
    inst->core->dyn = s->dyn;
    inst->mode = s->mode;
    inst->start_time = s->start_time;
    return fmi3OK;
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *state)
{
    (void)instance;
    if (state) {
        free(*state);
        *state = NULL;
    }
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState state, size_t *size)
{
    (void)instance; (void)state;
    *size = sizeof(Snapshot);
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState state,
                                 fmi3Byte serializedState[], size_t size)
{
    Instance *inst = (Instance *)instance;
    if (!inst || !state) return fmi3Error;
    if (size < sizeof(Snapshot)) return fail(inst, "serialization buffer too small%s", NULL);
    memcpy(serializedState, state, sizeof(Snapshot));
    return fmi3OK;
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[],
                                   size_t size, fmi3FMUState *state)
{
    Instance *inst = (Instance *)instance;
    Snapshot *s;
    if (!inst || !state) return fmi3Error;
    if (size != sizeof(Snapshot))
        return fail(inst, "serialized state has the wrong size (another build?)%s", NULL);
    s = (Snapshot *)malloc(sizeof(Snapshot));
    if (!s) return fail(inst, "out of memory restoring the FMU state%s", NULL);
    memcpy(s, serializedState, sizeof(Snapshot));
    *state = s;
    return fmi3OK;
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                        size_t nUnknowns, const fmi3ValueReference knowns[],
                                        size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                        fmi3Float64 sensitivity[], size_t nSensitivity)
{
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed;
    (void)sensitivity; (void)nSensitivity;
    if (!instance) return fmi3Error;
    return fail((Instance *)instance, "directional derivatives are not provided%s", NULL);
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                    size_t nUnknowns, const fmi3ValueReference knowns[],
                                    size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                    fmi3Float64 sensitivity[], size_t nSensitivity)
{
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed;
    (void)sensitivity; (void)nSensitivity;
    if (!instance) return fmi3Error;
    return fail((Instance *)instance, "adjoint derivatives are not provided%s", NULL);
}

/* ---- modes this FMU does not have ------------------------------------------------ */
#define UNSUPPORTED_MODE(Name)                                                                   \
    fmi3Status fmi3##Name(fmi3Instance instance)                                                 \
    {                                                                                            \
        if (!instance) return fmi3Error;                                                         \
        return fail((Instance *)instance, "fmi3" #Name " is not supported by this FMU%s", NULL);  \
    }

UNSUPPORTED_MODE(EnterConfigurationMode)
UNSUPPORTED_MODE(ExitConfigurationMode)
UNSUPPORTED_MODE(EvaluateDiscreteStates)
UNSUPPORTED_MODE(EnterContinuousTimeMode)

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[])
{
    (void)vr; (void)nvr; (void)intervals; (void)qualifiers;
    if (!instance) return fmi3Error;
    return fail((Instance *)instance, "this FMU has no clocks%s", NULL);
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[])
{
    (void)vr; (void)nvr; (void)counters; (void)resolutions; (void)qualifiers;
    if (!instance) return fmi3Error;
    return fail((Instance *)instance, "this FMU has no clocks%s", NULL);
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               fmi3Float64 shifts[])
{
    (void)vr; (void)nvr; (void)shifts;
    if (!instance) return fmi3Error;
    return fail((Instance *)instance, "this FMU has no clocks%s", NULL);
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                fmi3UInt64 counters[], fmi3UInt64 resolutions[])
{
    (void)vr; (void)nvr; (void)counters; (void)resolutions;
    if (!instance) return fmi3Error;
    return fail((Instance *)instance, "this FMU has no clocks%s", NULL);
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  const fmi3Float64 intervals[])
{
    (void)vr; (void)nvr; (void)intervals;
    if (!instance) return fmi3Error;
    return fail((Instance *)instance, "this FMU has no clocks%s", NULL);
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{
    (void)vr; (void)nvr; (void)counters; (void)resolutions;
    if (!instance) return fmi3Error;
    return fail((Instance *)instance, "this FMU has no clocks%s", NULL);
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               const fmi3Float64 shifts[])
{
    (void)vr; (void)nvr; (void)shifts;
    if (!instance) return fmi3Error;
    return fail((Instance *)instance, "this FMU has no clocks%s", NULL);
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{
    (void)vr; (void)nvr; (void)counters; (void)resolutions;
    if (!instance) return fmi3Error;
    return fail((Instance *)instance, "this FMU has no clocks%s", NULL);
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged,
                                    fmi3Boolean *nextEventTimeDefined, fmi3Float64 *nextEventTime)
{
    (void)discreteStatesNeedUpdate; (void)terminateSimulation; (void)nominalsOfContinuousStatesChanged;
    (void)valuesOfContinuousStatesChanged; (void)nextEventTimeDefined; (void)nextEventTime;
    if (!instance) return fmi3Error;
    return fail((Instance *)instance, "event mode is not supported%s", NULL);
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation)
{
    (void)noSetFMUStatePriorToCurrentPoint; (void)enterEventMode; (void)terminateSimulation;
    if (!instance) return fmi3Error;
    return fail((Instance *)instance, "model exchange is not supported%s", NULL);
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time)
{
    (void)time;
    if (!instance) return fmi3Error;
    return fail((Instance *)instance, "model exchange is not supported%s", NULL);
}

#define ME_ARRAY_STUB(Name, CType)                                                               \
    fmi3Status fmi3##Name(fmi3Instance instance, CType values[], size_t n)                       \
    {                                                                                            \
        (void)values; (void)n;                                                                   \
        if (!instance) return fmi3Error;                                                         \
        return fail((Instance *)instance, "model exchange is not supported%s", NULL);            \
    }
ME_ARRAY_STUB(SetContinuousStates, const fmi3Float64)
ME_ARRAY_STUB(GetContinuousStateDerivatives, fmi3Float64)
ME_ARRAY_STUB(GetEventIndicators, fmi3Float64)
ME_ARRAY_STUB(GetContinuousStates, fmi3Float64)
ME_ARRAY_STUB(GetNominalsOfContinuousStates, fmi3Float64)

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *n)
{
    if (!instance || !n) return fmi3Error;
    *n = 0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *n)
{
    if (!instance || !n) return fmi3Error;
    *n = 0;
    return fmi3OK;
}

/* ---- co-simulation ------------------------------------------------------------ */
fmi3Status fmi3EnterStepMode(fmi3Instance instance)
{
    Instance *inst = (Instance *)instance;
    if (!inst) return fmi3Error;
    if (inst->mode != MODE_STEP)
        return fail(inst, "fmi3EnterStepMode: the instance is not initialized%s", NULL);
    return fmi3OK;
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                    const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues)
{
    (void)vr; (void)nvr; (void)orders; (void)values; (void)nValues;
    if (!instance) return fmi3Error;
    return fail((Instance *)instance, "output derivatives are not supported%s", NULL);
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                      fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime)
{
    Instance *inst = (Instance *)instance;
    (void)currentCommunicationPoint; (void)noSetFMUStatePriorToCurrentPoint;
    if (!inst) return fmi3Error;
    if (eventHandlingNeeded) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (earlyReturn) *earlyReturn = fmi3False;
    if (inst->mode != MODE_STEP)
        return fail(inst, "fmi3DoStep: the instance is not initialized (or in error)%s", NULL);
    if (core_do_step(inst->core, communicationStepSize) != 0) {
        inst->mode = MODE_ERROR;
        if (lastSuccessfulTime) *lastSuccessfulTime = currentCommunicationPoint;
        return fail(inst, "step failed (see the messages above)%s", NULL);
    }
    if (lastSuccessfulTime) *lastSuccessfulTime = inst->core->dyn.time;
    return fmi3OK;
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime)
{
    (void)clockReference; (void)activationTime;
    if (!instance) return fmi3Error;
    return fail((Instance *)instance, "scheduled execution is not supported%s", NULL);
}
