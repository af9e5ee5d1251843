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
#include "fmu_slave.h"
#include "fmu_variables.h"

typedef struct {
    FmuSlave slave;                 /* everything FMI-version independent */
    fmi2CallbackFunctions cb;
    char name[128];
} Instance;

/* The FMI 2 logger takes a printf format: pass the message itself with '%' doubled and no
 * variadic arguments, so that importers that cannot read variadic arguments (ctypes) get
 * the whole text too. */
static void log_message(void *env, int level, const char *message)
{
    Instance *inst = (Instance *)env;
    fmi2Status status = level >= 2 ? fmi2Error : (level == 1 ? fmi2Warning : fmi2OK);
    const char *category = fmu_slave_log_category(&inst->slave, level);
    char text[2048];
    size_t i, j = 0;
    if (!inst->cb.logger || !category) return;
    for (i = 0; message[i] && j + 2 < sizeof text; i++) {
        if (message[i] == '%') text[j++] = '%';
        text[j++] = message[i];
    }
    text[j] = 0;
    inst->cb.logger(inst->cb.componentEnvironment, inst->name, status, category, text);
}

static fmi2Status status_of(int rc) { return rc == 0 ? fmi2OK : fmi2Error; }

#define SLAVE(c) (&((Instance *)(c))->slave)

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
    if (!c) return fmi2Error;
    return status_of(fmu_slave_set_logging(SLAVE(c), loggingOn ? 1 : 0, nCategories, categories));
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
    if (fmuType != fmi2CoSimulation || !fmuResourceLocation ||
        uri_to_path(fmuResourceLocation, path, sizeof path) != 0) {
        log_message(inst, 2, fmuType != fmi2CoSimulation ? "this FMU supports co-simulation only"
                                                         : "invalid resource location");
        free(inst);
        return NULL;
    }
    if (fmu_slave_create(&inst->slave, fmuGUID, path, FMU_VARS, FMU_N_VARS, FMU_INSTANTIATION_TOKEN,
                         log_message, inst) != 0) {
        free(inst);
        return NULL;
    }
    fmu_slave_set_logging(&inst->slave, loggingOn ? 1 : 0, 1, (const char *const[]){"logEvents"});
    return inst;
}

void fmi2FreeInstance(fmi2Component c)
{
    if (!c) return;
    fmu_slave_destroy(SLAVE(c));
    free(c);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    if (!c) return fmi2Error;
    return status_of(fmu_slave_set_start_time(SLAVE(c), startTime));
}

/* Life-cycle calls that only forward to the slave. */
#define FORWARD(Name, slave_function)                                                           \
    fmi2Status fmi2##Name(fmi2Component c)                                                      \
    {                                                                                           \
        if (!c) return fmi2Error;                                                               \
        return status_of(slave_function(SLAVE(c)));                                             \
    }
FORWARD(EnterInitializationMode, fmu_slave_enter_init)
FORWARD(ExitInitializationMode, fmu_slave_exit_init)
FORWARD(Terminate, fmu_slave_terminate)
FORWARD(Reset, fmu_slave_reset)

/* ---- getters and setters (all variables of this variant are scalars) ----------------- */
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    if (!c) return fmi2Error;
    return status_of(fmu_slave_get(SLAVE(c), vr, nvr, FT_REAL, value, nvr));
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[])
{
    if (!c) return fmi2Error;
    return status_of(fmu_slave_set(SLAVE(c), vr, nvr, FT_REAL, value, nvr));
}

/* Integer and Boolean go through a double buffer (few values: switches and selectors). */
#define ACCESSORS(Name, CType, FT, TO_C)                                                        \
    fmi2Status fmi2Get##Name(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,        \
                             CType value[])                                                     \
    {                                                                                           \
        double *buf;                                                                            \
        size_t i;                                                                               \
        int rc;                                                                                 \
        if (!c) return fmi2Error;                                                               \
        if (nvr == 0) return fmi2OK;                                                            \
        if (!(buf = (double *)malloc(nvr * sizeof(double)))) return fmi2Error;                  \
        rc = fmu_slave_get(SLAVE(c), vr, nvr, FT, buf, nvr);                                    \
        for (i = 0; rc == 0 && i < nvr; i++) value[i] = TO_C(buf[i]);                           \
        free(buf);                                                                              \
        return status_of(rc);                                                                   \
    }                                                                                           \
    fmi2Status fmi2Set##Name(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,        \
                             const CType value[])                                               \
    {                                                                                           \
        double *buf;                                                                            \
        size_t i;                                                                               \
        int rc;                                                                                 \
        if (!c) return fmi2Error;                                                               \
        if (nvr == 0) return fmi2OK;                                                            \
        if (!value || !(buf = (double *)malloc(nvr * sizeof(double)))) return fmi2Error;        \
        for (i = 0; i < nvr; i++) buf[i] = (double)value[i];                                    \
        rc = fmu_slave_set(SLAVE(c), vr, nvr, FT, buf, nvr);                                    \
        free(buf);                                                                              \
        return status_of(rc);                                                                   \
    }

#define AS_INT(x) ((fmi2Integer)fmu_to_int(x))
#define AS_BOOL(x) ((x) != 0.0 ? fmi2True : fmi2False)
ACCESSORS(Integer, fmi2Integer, FT_INTEGER, AS_INT)
ACCESSORS(Boolean, fmi2Boolean, FT_BOOLEAN, AS_BOOL)

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         fmi2String value[])
{
    (void)vr; (void)value;
    if (!c) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    log_message(c, 2, "this FMU has no String variables");
    return fmi2Error;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[])
{
    (void)vr; (void)value;
    if (!c) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    log_message(c, 2, "this FMU has no String variables");
    return fmi2Error;
}

/* ---- FMU state ------------------------------------------------------------------- */
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    if (!c) return fmi2Error;
    return status_of(fmu_slave_get_state(SLAVE(c), state));
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    if (!c) return fmi2Error;
    return status_of(fmu_slave_set_state(SLAVE(c), state));
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    (void)c;
    fmu_slave_free_state(state);
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size)
{
    (void)state;
    if (!c || !size) return fmi2Error;
    *size = fmu_slave_state_size();
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size)
{
    if (!c) return fmi2Error;
    return status_of(fmu_slave_serialize_state(SLAVE(c), state, (unsigned char *)bytes, size));
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size,
                                   fmi2FMUstate *state)
{
    if (!c) return fmi2Error;
    return status_of(fmu_slave_deserialize_state(SLAVE(c), (const unsigned char *)bytes, size, state));
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[],
                                        size_t nUnknown, const fmi2ValueReference vKnown_ref[],
                                        size_t nKnown, const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    if (!c) return fmi2Error;
    log_message(c, 2, "directional derivatives are not provided");
    return fmi2Error;
}

/* ---- co-simulation ------------------------------------------------------------ */
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    (void)vr; (void)nvr; (void)order; (void)value;
    if (!c) return fmi2Error;
    log_message(c, 2, "input derivatives are not supported");
    return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    (void)vr; (void)nvr; (void)order; (void)value;
    if (!c) return fmi2Error;
    log_message(c, 2, "output derivatives are not supported");
    return fmi2Error;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!c) return fmi2Error;
    return status_of(fmu_slave_do_step(SLAVE(c), currentCommunicationPoint, communicationStepSize));
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    if (!c) return fmi2Error;
    log_message(c, 2, "fmi2CancelStep: steps are synchronous");
    return fmi2Error;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    (void)s; (void)value;
    if (!c) return fmi2Error;
    log_message(c, 2, "fmi2GetStatus: steps are synchronous");
    return fmi2Error;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    if (!c || !value) return fmi2Error;
    if (s == fmi2LastSuccessfulTime) {
        *value = SLAVE(c)->core->dyn.time;
        return fmi2OK;
    }
    log_message(c, 2, "fmi2GetRealStatus: unsupported status kind");
    return fmi2Error;
}

#define UNSUPPORTED_STATUS(Name, CType)                                                         \
    fmi2Status fmi2Get##Name##Status(fmi2Component c, const fmi2StatusKind s, CType *value)     \
    {                                                                                           \
        (void)s; (void)value;                                                                   \
        if (!c) return fmi2Error;                                                               \
        log_message(c, 2, "fmi2Get" #Name "Status: unsupported");                               \
        return fmi2Error;                                                                       \
    }
UNSUPPORTED_STATUS(Integer, fmi2Integer)
UNSUPPORTED_STATUS(Boolean, fmi2Boolean)
UNSUPPORTED_STATUS(String, fmi2String)
