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
#include "fmu_slave.h"
#include "fmu_variables.h"

typedef struct {
    FmuSlave slave;                 /* everything FMI-version independent */
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
} Instance;

static void log_message(void *env, int level, const char *message)
{
    Instance *inst = (Instance *)env;
    fmi3Status status = level >= 2 ? fmi3Error : (level == 1 ? fmi3Warning : fmi3OK);
    const char *category = fmu_slave_log_category(&inst->slave, level);
    if (inst->log && category) inst->log(inst->env, status, category, message);
}

static fmi3Status status_of(int rc) { return rc == 0 ? fmi3OK : fmi3Error; }

static fmi3Status fail(fmi3Instance instance, const char *message)
{
    log_message(instance, 2, message);
    return fmi3Error;
}

#define SLAVE(c) (&((Instance *)(c))->slave)

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[])
{
    if (!instance) return fmi3Error;
    return status_of(fmu_slave_set_logging(SLAVE(instance), loggingOn ? 1 : 0, nCategories, categories));
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
    (void)instanceName; (void)visible; (void)eventModeUsed; (void)earlyReturnAllowed;
    (void)requiredIntermediateVariables; (void)nRequiredIntermediateVariables; (void)intermediateUpdate;
    inst = (Instance *)calloc(1, sizeof(Instance));
    if (!inst) return NULL;
    inst->env = instanceEnvironment;
    inst->log = logMessage;
    if (fmu_slave_create(&inst->slave, instantiationToken, resourcePath, FMU_VARS, FMU_N_VARS,
                         FMU_INSTANTIATION_TOKEN, log_message, inst) != 0) {
        free(inst);
        return NULL;
    }
    fmu_slave_set_logging(&inst->slave, loggingOn ? 1 : 0, 1, (const char *const[]){"logEvents"});
    return inst;
}

void fmi3FreeInstance(fmi3Instance instance)
{
    if (!instance) return;
    fmu_slave_destroy(SLAVE(instance));
    free(instance);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                       fmi3Float64 tolerance, fmi3Float64 startTime,
                                       fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    if (!instance) return fmi3Error;
    if (fmu_slave_set_start_time(SLAVE(instance), startTime) != 0) return fmi3Error;
    return status_of(fmu_slave_enter_init(SLAVE(instance)));
}

/* Life-cycle calls that only forward to the slave. */
#define FORWARD(Name, slave_function)                                                            \
    fmi3Status fmi3##Name(fmi3Instance instance)                                                 \
    {                                                                                            \
        if (!instance) return fmi3Error;                                                         \
        return status_of(slave_function(SLAVE(instance)));                                       \
    }
FORWARD(ExitInitializationMode, fmu_slave_exit_init)
FORWARD(Terminate, fmu_slave_terminate)
FORWARD(Reset, fmu_slave_reset)

fmi3Status fmi3EnterEventMode(fmi3Instance instance)
{
    if (!instance) return fmi3Error;
    return fail(instance, "event mode is not supported");
}


/* ---- getters and setters (arrays: all elements in order; sets are atomic) -------------- */
fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          fmi3Float64 values[], size_t nValues)
{
    if (!instance) return fmi3Error;
    return status_of(fmu_slave_get(SLAVE(instance), vr, nvr, FT_REAL, values, nValues));
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Float64 values[], size_t nValues)
{
    if (!instance) return fmi3Error;
    return status_of(fmu_slave_set(SLAVE(instance), vr, nvr, FT_REAL, values, nValues));
}

/* Int32 and Boolean go through a double buffer (few values: selectors and switches). */
#define CONVERTING_ACCESSORS(Name, CType, FT, TO_C)                                             \
    fmi3Status fmi3Get##Name(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,   \
                             CType values[], size_t nValues)                                     \
    {                                                                                            \
        double *buf;                                                                             \
        size_t i;                                                                                \
        int rc;                                                                                  \
        if (!instance) return fmi3Error;                                                         \
        if (nvr == 0 && nValues == 0) return fmi3OK;                                             \
        if (!(buf = (double *)malloc((nValues ? nValues : 1) * sizeof(double)))) return fmi3Error; \
        rc = fmu_slave_get(SLAVE(instance), vr, nvr, FT, buf, nValues);                          \
        for (i = 0; rc == 0 && i < nValues; i++) values[i] = TO_C(buf[i]);                       \
        free(buf);                                                                               \
        return status_of(rc);                                                                    \
    }                                                                                            \
    fmi3Status fmi3Set##Name(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,   \
                             const CType values[], size_t nValues)                               \
    {                                                                                            \
        double *buf;                                                                             \
        size_t i;                                                                                \
        int rc;                                                                                  \
        if (!instance) return fmi3Error;                                                         \
        if (nvr == 0 && nValues == 0) return fmi3OK;                                             \
        if (nValues > 0 && !values) return fail(instance, "null value array");                   \
        if (!(buf = (double *)malloc((nValues ? nValues : 1) * sizeof(double)))) return fmi3Error; \
        for (i = 0; i < nValues; i++) buf[i] = (double)values[i];                                \
        rc = fmu_slave_set(SLAVE(instance), vr, nvr, FT, buf, nValues);                          \
        free(buf);                                                                               \
        return status_of(rc);                                                                    \
    }

#define TO_INT32(x) ((fmi3Int32)fmu_to_int(x))
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
        return fail(instance, "this FMU has no " #Name " variables");        \
    }                                                                                            \
    fmi3Status fmi3Set##Name(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,   \
                             const CType values[], size_t nValues)                               \
    {                                                                                            \
        (void)vr; (void)values; (void)nValues;                                                   \
        if (!instance) return fmi3Error;                                                         \
        if (nvr == 0) return fmi3OK;                                                             \
        return fail(instance, "this FMU has no " #Name " variables");        \
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
    return fail(instance, "this FMU has no Binary variables");
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues)
{
    (void)vr; (void)valueSizes; (void)values; (void)nValues;
    if (!instance) return fmi3Error;
    if (nvr == 0) return fmi3OK;
    return fail(instance, "this FMU has no Binary variables");
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                        fmi3Clock values[])
{
    (void)vr; (void)values;
    if (!instance) return fmi3Error;
    if (nvr == 0) return fmi3OK;
    return fail(instance, "this FMU has no clocks");
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                        const fmi3Clock values[])
{
    (void)vr; (void)values;
    if (!instance) return fmi3Error;
    if (nvr == 0) return fmi3OK;
    return fail(instance, "this FMU has no clocks");
}

/* ---- dependencies, state, derivatives ------------------------------------------ */
fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference vr,
                                               size_t *nDependencies)
{
    (void)vr; (void)nDependencies;
    if (!instance) return fmi3Error;
    return fail(instance, "variable dependencies are not provided");
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
    return fail(instance, "variable dependencies are not provided");
}

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *state)
{
    if (!instance) return fmi3Error;
    return status_of(fmu_slave_get_state(SLAVE(instance), state));
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState state)
{
    if (!instance) return fmi3Error;
    return status_of(fmu_slave_set_state(SLAVE(instance), state));
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *state)
{
    (void)instance;
    fmu_slave_free_state(state);
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState state, size_t *size)
{
    (void)state;
    if (!instance || !size) return fmi3Error;
    *size = fmu_slave_state_size();
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState state,
                                 fmi3Byte serializedState[], size_t size)
{
    if (!instance) return fmi3Error;
    return status_of(fmu_slave_serialize_state(SLAVE(instance), state, serializedState, size));
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[],
                                   size_t size, fmi3FMUState *state)
{
    if (!instance) return fmi3Error;
    return status_of(fmu_slave_deserialize_state(SLAVE(instance), serializedState, size, state));
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                        size_t nUnknowns, const fmi3ValueReference knowns[],
                                        size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                        fmi3Float64 sensitivity[], size_t nSensitivity)
{
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed;
    (void)sensitivity; (void)nSensitivity;
    if (!instance) return fmi3Error;
    return fail(instance, "directional derivatives are not provided");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                    size_t nUnknowns, const fmi3ValueReference knowns[],
                                    size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                    fmi3Float64 sensitivity[], size_t nSensitivity)
{
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed;
    (void)sensitivity; (void)nSensitivity;
    if (!instance) return fmi3Error;
    return fail(instance, "adjoint derivatives are not provided");
}

/* ---- modes this FMU does not have ------------------------------------------------ */
#define UNSUPPORTED_MODE(Name)                                                                   \
    fmi3Status fmi3##Name(fmi3Instance instance)                                                 \
    {                                                                                            \
        if (!instance) return fmi3Error;                                                         \
        return fail(instance, "fmi3" #Name " is not supported by this FMU");  \
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
    return fail(instance, "this FMU has no clocks");
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[])
{
    (void)vr; (void)nvr; (void)counters; (void)resolutions; (void)qualifiers;
    if (!instance) return fmi3Error;
    return fail(instance, "this FMU has no clocks");
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               fmi3Float64 shifts[])
{
    (void)vr; (void)nvr; (void)shifts;
    if (!instance) return fmi3Error;
    return fail(instance, "this FMU has no clocks");
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                fmi3UInt64 counters[], fmi3UInt64 resolutions[])
{
    (void)vr; (void)nvr; (void)counters; (void)resolutions;
    if (!instance) return fmi3Error;
    return fail(instance, "this FMU has no clocks");
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  const fmi3Float64 intervals[])
{
    (void)vr; (void)nvr; (void)intervals;
    if (!instance) return fmi3Error;
    return fail(instance, "this FMU has no clocks");
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{
    (void)vr; (void)nvr; (void)counters; (void)resolutions;
    if (!instance) return fmi3Error;
    return fail(instance, "this FMU has no clocks");
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               const fmi3Float64 shifts[])
{
    (void)vr; (void)nvr; (void)shifts;
    if (!instance) return fmi3Error;
    return fail(instance, "this FMU has no clocks");
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                const fmi3UInt64 counters[], const fmi3UInt64 resolutions[])
{
    (void)vr; (void)nvr; (void)counters; (void)resolutions;
    if (!instance) return fmi3Error;
    return fail(instance, "this FMU has no clocks");
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
    return fail(instance, "event mode is not supported");
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation)
{
    (void)noSetFMUStatePriorToCurrentPoint; (void)enterEventMode; (void)terminateSimulation;
    if (!instance) return fmi3Error;
    return fail(instance, "model exchange is not supported");
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time)
{
    (void)time;
    if (!instance) return fmi3Error;
    return fail(instance, "model exchange is not supported");
}

#define ME_ARRAY_STUB(Name, CType)                                                               \
    fmi3Status fmi3##Name(fmi3Instance instance, CType values[], size_t n)                       \
    {                                                                                            \
        (void)values; (void)n;                                                                   \
        if (!instance) return fmi3Error;                                                         \
        return fail(instance, "model exchange is not supported");            \
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
    if (!instance) return fmi3Error;
    if (SLAVE(instance)->mode != FMU_MODE_STEP)
        return fail(instance, "fmi3EnterStepMode: the instance is not initialized");
    return fmi3OK;
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                    const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues)
{
    (void)vr; (void)nvr; (void)orders; (void)values; (void)nValues;
    if (!instance) return fmi3Error;
    return fail(instance, "output derivatives are not supported");
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                      fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime)
{
    int rc;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!instance) return fmi3Error;
    if (eventHandlingNeeded) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (earlyReturn) *earlyReturn = fmi3False;
    rc = fmu_slave_do_step(SLAVE(instance), currentCommunicationPoint, communicationStepSize);
    if (lastSuccessfulTime) *lastSuccessfulTime = SLAVE(instance)->core->dyn.time;
    return status_of(rc);
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime)
{
    (void)clockReference; (void)activationTime;
    if (!instance) return fmi3Error;
    return fail(instance, "scheduled execution is not supported");
}
